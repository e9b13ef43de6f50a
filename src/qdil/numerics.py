"""Reproducible numerics: MKL's conditional numerical reproducibility (CNR), set by qdil itself.

On Intel CPUs, MKL (torch's CPU BLAS) picks kernels whose last bits depend on how the inputs
sit in memory, unless a CNR mode is in force before MKL's first call. ``import qdil`` sets
``MKL_CBWR`` (default ``AUTO,STRICT``); why and what it costs: docs/concepts/reproducibility.md.
"""

from __future__ import annotations

import ctypes
import os
import sys
import warnings
from functools import cache

ENV = "MKL_CBWR"
ATEN_ENV = "ATEN_CPU_CAPABILITY"
DEFAULT_MODE = "AUTO,STRICT"
STRICT = 0x10000
BRANCHES = {
    "AUTO": 2,
    "COMPATIBLE": 3,
    "SSE2": 4,
    "SSSE3": 6,
    "SSE4_1": 7,
    "SSE4_2": 8,
    "AVX": 9,
    "AVX2": 10,
    "AVX512": 12,
    "AVX512_E1": 14,
}
"""MKL's CNR branches (``mkl_service.h``) that a user may ask for by name."""
_NAMES = {code: name for name, code in BRANCHES.items()} | {0: "OFF", 1: "OFF"}
_ALL, _MODE_LOCKED = ~0, -8


class ReproducibilityWarning(UserWarning):
    """MKL computed before qdil could put it in a reproducible mode."""


def parse(mode: str) -> int:
    """MKL's code of a mode such as ``AUTO,STRICT`` or ``AVX2``.

    Raises:
        ValueError: naming ``MKL_CBWR`` and the modes it accepts.
    """
    branch, _, flag = mode.strip().upper().partition(",")
    if branch not in BRANCHES or flag not in ("", "STRICT"):
        raise ValueError(
            f"{ENV}={mode!r} is not an MKL reproducibility mode: use one of "
            f"{', '.join(BRANCHES)}, optionally followed by ',STRICT', or OFF (qdil's default "
            f"is {DEFAULT_MODE}; unset {ENV} to get it)"
        )
    return BRANCHES[branch] | (STRICT if flag else 0)


def name(code: int) -> str:
    """The mode's name (``AVX512_E1,STRICT``) from MKL's code."""
    branch = _NAMES.get(code & ~STRICT, f"BRANCH_{code & ~STRICT}")
    return branch + (",STRICT" if code & STRICT else "")


def requested() -> str:
    """The mode qdil asks MKL for: ``MKL_CBWR`` as set, else :data:`DEFAULT_MODE`."""
    return os.environ.get(ENV, DEFAULT_MODE)


@cache
def _mkl() -> ctypes.CDLL | None:
    """Torch's CPU library where it carries MKL's CNR functions (x86), else ``None``."""
    import torch

    path = os.path.join(os.path.dirname(torch.__file__), "lib", "libtorch_cpu.so")
    try:
        lib = ctypes.CDLL(path)
        for function in ("mkl_serv_cbwr_get", "mkl_serv_cbwr_set", "mkl_serv_cbwr_get_auto_branch"):
            getattr(lib, function)
    except (OSError, AttributeError):
        return None  # no MKL (ARM, macOS): torch's BLAS there has no alignment-dependent kernels
    return lib


def configure() -> None:
    """Put MKL in the requested reproducible mode, or warn that it is too late.

    Sets ``MKL_CBWR`` for this process and every process it starts (Ray workers,
    subprocesses), which MKL reads at its first call. If torch is already imported, the mode
    is also set through MKL's own ``mkl_cbwr_set``; that fails once MKL has computed, and a
    :class:`ReproducibilityWarning` says so.

    ``MKL_CBWR=OFF`` leaves MKL as it is, with a warning (benchmarks measure the mode's cost
    that way).

    Raises:
        ValueError: ``MKL_CBWR`` holds no valid mode.
    """
    if requested().strip().upper() == "OFF":
        del os.environ[ENV]  # MKL would read an unknown value as AUTO
        warnings.warn(
            f"{ENV}=OFF: MKL is left without a reproducibility mode, so on Intel CPUs runs "
            "with the same seed can differ in the last bits",
            ReproducibilityWarning,
            stacklevel=3,
        )
        return
    code = parse(requested())
    os.environ[ENV] = name(code)  # MKL reads only the upper-case spelling
    if "torch" not in sys.modules or (lib := _mkl()) is None:
        return
    if lib.mkl_serv_cbwr_set(ctypes.c_int(code)) == _MODE_LOCKED and not in_force():
        warnings.warn(
            f"torch computed with MKL before qdil was imported, so MKL runs in mode "
            f"{mkl_mode()} instead of {requested()}: on Intel CPUs results can then differ "
            f"in the last bits between runs with the same seed. Import qdil before computing "
            f"with torch, or set {ENV}={requested()} in the environment before starting "
            "Python.",
            ReproducibilityWarning,
            stacklevel=3,
        )


def _code() -> int | None:
    lib = _mkl()
    return None if lib is None else lib.mkl_serv_cbwr_get(ctypes.c_int(_ALL))


def mkl_mode() -> str | None:
    """The mode in force as MKL reports it (``None`` where torch has no MKL)."""
    code = _code()
    return None if code is None else name(code)


def _resolve(lib: ctypes.CDLL, code: int) -> int:
    """``code`` with the AUTO branch replaced by the one MKL chooses on this CPU."""
    if code & ~STRICT == BRANCHES["AUTO"]:
        return lib.mkl_serv_cbwr_get_auto_branch() | (code & STRICT)
    return code


def resolved_mode() -> str | None:
    """The mode in force with ``AUTO`` replaced by the branch MKL chose on this CPU.

    Workers on other machines get this, so that every node computes with the head's
    kernels, or says it cannot (:func:`require`).
    """
    lib, code = _mkl(), _code()
    return None if lib is None or code is None else name(_resolve(lib, code))


def in_force(mode: str | None = None) -> bool:
    """Whether MKL runs in ``mode`` (default: :func:`requested`); true without MKL."""
    lib, code = _mkl(), _code()
    if lib is None or code is None:
        return True
    return _resolve(lib, code) == _resolve(lib, parse(mode or requested()))


def require(mode: str | None = None, where: str = "this process") -> None:
    """Raise unless MKL runs in ``mode`` (default: :func:`requested`).

    Raises:
        RuntimeError: naming where, the mode wanted and the mode in force.
    """
    if not in_force(mode):
        raise RuntimeError(
            f"MKL runs in mode {mkl_mode()} in {where}, not {mode or requested()}: results "
            f"would differ in the last bits from the head's. Where a node's CPU lacks that "
            f"branch, set {ENV} to one every node has (for example AVX2,STRICT) before "
            "starting the head; see docs/concepts/reproducibility.md"
        )


def worker_env() -> dict[str, str]:
    """The variables that make a worker process compute with this process's kernels.

    MKL's mode with its branch resolved (``AVX512_E1,STRICT``, not ``AUTO,STRICT``) and
    torch's vector instruction set (``avx512``): a worker on another CPU either takes the
    same kernels or :func:`require_env` refuses it.
    """
    import torch

    env = {ATEN_ENV: torch.backends.cpu.get_cpu_capability().lower()}
    if (mode := resolved_mode()) is not None:
        env[ENV] = mode
    return env


def require_env(env: dict[str, str], where: str) -> None:
    """Raise unless this process computes as :func:`worker_env` ``env`` asks.

    Raises:
        RuntimeError: naming ``where``, what was asked and what is in force.
    """
    import torch

    if env.get(ENV, "OFF") != "OFF":  # OFF: the head runs without a mode, and so may we
        require(env[ENV], where)
    capability = torch.backends.cpu.get_cpu_capability().lower()
    if env.get(ATEN_ENV, capability) != capability:
        raise RuntimeError(
            f"torch uses {capability} kernels in {where}, not the head's {env[ATEN_ENV]}: "
            f"results would differ in the last bits. Set {ATEN_ENV} to a level every node "
            "has (for example avx2) before starting the head; see "
            "docs/concepts/reproducibility.md"
        )
