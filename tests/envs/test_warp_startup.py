"""What a Warp run prints at start: no CUDA alarm without a driver, one line before the compile."""

from __future__ import annotations

import subprocess
import sys
from types import SimpleNamespace

import pytest

from qdil.envs import warp_startup


def test_the_compile_is_announced_once_per_process(monkeypatch, capsys) -> None:
    monkeypatch.setattr(warp_startup, "_announced", False)
    warp = SimpleNamespace(config=SimpleNamespace(kernel_cache_dir="/cache/warp/1.0"))
    warp_startup.announce_warp_kernels(warp)
    warp_startup.announce_warp_kernels(warp)  # the eval env, built next
    lines = capsys.readouterr().err.splitlines()
    assert lines == [
        "loading MuJoCo Warp kernels (a model's first run compiles them, tens of seconds; "
        "cached after, in /cache/warp/1.0)"
    ]


def test_native_stderr_is_silenced_inside_the_block_only(capfd) -> None:
    import ctypes

    libc = ctypes.CDLL(None)
    with warp_startup.native_stderr_silenced():
        libc.write(2, b"hidden\n", 7)
    with warp_startup.native_stderr_silenced(False):
        libc.write(2, b"shown\n", 6)
    libc.write(2, b"after\n", 6)
    assert capfd.readouterr().err == "shown\nafter\n"


def test_a_machine_without_cuda_driver_gets_no_cuda_warning() -> None:
    pytest.importorskip("mujoco_warp", reason="the warp extra is not installed")
    if warp_startup.cuda_driver_found():
        pytest.skip("this machine has a CUDA driver: Warp has nothing to warn about")
    code = "from qdil.envs.warp_startup import import_warp as w; print(w()[0].is_cuda_available())"
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=True
    )
    assert done.stdout.strip() == "False"
    assert "CUDA" not in done.stderr, done.stderr
