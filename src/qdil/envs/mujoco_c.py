"""MuJoCo's C functions called from numba kernels that numba can cache on disk.

A numba kernel that calls a ``ctypes`` function has the function's address built into its
machine code. The address changes from one process to the next, so numba refuses to cache
such a kernel ("uses dynamic globals") and compiled the physics kernels again at every
start (about 6 s). Here the kernels receive the addresses as an argument (:data:`MUJOCO_C`)
and call them through intrinsics that turn the integer into a function pointer at run
time: their code holds no address, and ``cache=True`` keeps it on disk (:func:`cached_njit`).

Where the cache goes is numba's choice: ``$NUMBA_CACHE_DIR`` if set, else the
``__pycache__`` folder beside the source when it is writable (a source checkout), else the
user's cache folder (``~/.cache/numba`` on Linux; a read-only pip install). A cached kernel
is rebuilt when its source file changes, and for another CPU model.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import mujoco
import numba
from llvmlite import ir
from numba import types
from numba.extending import intrinsic


def _libmujoco() -> ctypes.CDLL:
    """The MuJoCo shared library that the ``mujoco`` Python package already loaded."""
    folder = Path(mujoco.__file__).parent
    for pattern in ("libmujoco.so*", "libmujoco*.dylib", "mujoco.dll"):
        found = sorted(folder.glob(pattern))
        if found:
            return ctypes.CDLL(str(found[0]))
    raise ImportError(
        f"could not find the MuJoCo shared library in {folder}; reinstall the `mujoco` package"
    )


class MujocoC(NamedTuple):
    """Addresses of the MuJoCo C functions the physics kernels call (numba: a tuple of ints)."""

    mj_step: int
    mj_step1: int
    mj_forward_skip: int
    mj_check_acc: int
    mj_euler: int
    mj_runge_kutta: int
    mj_implicit: int
    mj_forward: int
    mj_reset_data: int
    mj_rne_post_constraint: int
    mju_copy: int


def _address(library: ctypes.CDLL, name: str) -> int:
    return ctypes.cast(getattr(library, name), ctypes.c_void_p).value


_LIB = _libmujoco()
MUJOCO_C = MujocoC(
    *(
        _address(_LIB, name)
        for name in (
            "mj_step",
            "mj_step1",
            "mj_forwardSkip",
            "mj_checkAcc",
            "mj_Euler",
            "mj_RungeKutta",
            "mj_implicit",
            "mj_forward",
            "mj_resetData",
            "mj_rnePostConstraint",
            "mju_copy",
        )
    )
)
"""The addresses in this process; pass them to the kernels, never bake them in."""


def _codegen(c_types: tuple[types.Integer, ...]) -> Callable:
    """Code that calls ``void f(c_types...)`` at the address in the first argument."""

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        address, *values = args
        values = [
            context.cast(builder, value, numba_type, c_type)
            for value, numba_type, c_type in zip(values, signature.args[1:], c_types, strict=True)
        ]
        function_type = ir.FunctionType(
            ir.VoidType(), [context.get_value_type(c_type) for c_type in c_types]
        )
        address = context.cast(builder, address, signature.args[0], types.int64)
        builder.call(builder.inttoptr(address, function_type.as_pointer()), values)
        return context.get_dummy_value()

    return codegen


def _integers(*values: Any) -> bool:
    return all(isinstance(value, types.Integer) for value in values)


# Pointers are int64 (every 64-bit ABI passes a pointer in the register of an int64); C's
# int is int32. One intrinsic per signature: numba's intrinsics take no *args.
_PP = (types.int64, types.int64)
_PPI = (*_PP, types.int32)
_PPII = (*_PPI, types.int32)


@intrinsic
def call_pp(typingctx: Any, address: Any, a: Any, b: Any) -> Any:
    """``f(ptr a, ptr b)`` for the C function at ``address`` (``mj_step(m, d)``, ...)."""
    if _integers(address, a, b):
        return types.void(address, a, b), _codegen(_PP)
    return None


@intrinsic
def call_ppi(typingctx: Any, address: Any, a: Any, b: Any, n: Any) -> Any:
    """``f(ptr a, ptr b, int n)`` (``mju_copy(dst, src, n)``, ``mj_RungeKutta(m, d, N)``)."""
    if _integers(address, a, b, n):
        return types.void(address, a, b, n), _codegen(_PPI)
    return None


@intrinsic
def call_ppii(typingctx: Any, address: Any, a: Any, b: Any, n: Any, k: Any) -> Any:
    """``f(ptr a, ptr b, int n, int k)`` (``mj_forwardSkip(m, d, skipstage, skipsensor)``)."""
    if _integers(address, a, b, n, k):
        return types.void(address, a, b, n, k), _codegen(_PPII)
    return None


def cached_njit(**options: Any) -> Callable:
    """``numba.njit(cache=True, **options)``, or without the cache where none can be written.

    numba raises at decoration when no cache folder is writable (a read-only install and a
    read-only home): the kernel then compiles at every start, as it did before caching.
    """

    def decorate(function: Callable) -> Callable:
        try:
            return numba.njit(cache=True, **options)(function)
        except RuntimeError:  # "cannot cache function ...: no locator available"
            return numba.njit(**options)(function)

    return decorate
