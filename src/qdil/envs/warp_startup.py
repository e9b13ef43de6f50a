"""Starting Warp: its import, no false alarm, and a word before a long wait.

:func:`import_warp` imports Warp and MuJoCo Warp (or says how to install them). Two things
a user met on the Warp backend's CPU device:

- Warp's C library prints "Warp CUDA warning: Could not find or load the NVIDIA CUDA
  driver" on every machine without one, whatever ``warp.config`` says. Such a machine can
  only run Warp on its CPU, so the line says nothing; :func:`cuda_driver_found` tells
  ``import_warp`` to initialise Warp with the C library's stderr silenced there.
- MuJoCo Warp compiles its kernels the first time a model runs (about 30 s on 2 CPU
  cores) and loads them from Warp's kernel cache after; :func:`announce_warp_kernels`
  says so, once per process, when the environment is built.
"""

from __future__ import annotations

import ctypes
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

_CUDA_DRIVERS = {"win32": ("nvcuda.dll",), "darwin": ()}
_announced = False


def cuda_driver_found() -> bool:
    """Whether this machine has an NVIDIA CUDA driver library that Warp could load."""
    for name in _CUDA_DRIVERS.get(sys.platform, ("libcuda.so", "libcuda.so.1")):
        try:
            ctypes.CDLL(name)
        except OSError:
            continue
        return True
    return False


@contextmanager
def native_stderr_silenced(silence: bool = True) -> Iterator[None]:
    """Inside the block, what C code writes to file descriptor 2 goes to ``/dev/null``.

    Args:
        silence: ``False`` leaves stderr alone (the block runs as it is).
    """
    if not silence:
        yield
        return
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def announce_warp_kernels(warp: Any) -> None:
    """Say, once per process, that MuJoCo Warp's kernels load now and may compile first.

    Args:
        warp: the initialised ``warp`` module (its kernel cache folder is named).
    """
    global _announced
    if _announced:
        return
    _announced = True
    print(
        "loading MuJoCo Warp kernels (a model's first run compiles them, tens of seconds; "
        f"cached after, in {warp.config.kernel_cache_dir})",
        file=sys.stderr,
        flush=True,
    )


def import_warp() -> tuple[Any, Any]:
    """``(warp, mujoco_warp)``, or an ImportError that says how to install them."""
    try:
        import warp

        warp.config.quiet = True  # before mujoco_warp's import initialises Warp (banner)
        warp.config.log_level = warp.LOG_WARNING  # no line per kernel module loaded
        # without a CUDA driver Warp's C library prints a "Warp CUDA warning" whatever the
        # config; such a machine runs Warp on its CPU only, so the line is noise there
        with native_stderr_silenced(not cuda_driver_found()):
            warp.init()
        import mujoco_warp
    except ImportError as error:
        raise ImportError(
            "env.backend: warp needs MuJoCo Warp; install it with "
            '`pip install -e ".[warp]"` (mujoco-warp and warp-lang)'
        ) from error
    return warp, mujoco_warp
