"""Same seed, same bits: MKL runs in a reproducible mode wherever qdil computes.

On AMD CPUs MKL takes code paths whose results happen not to vary, so equality tests alone
pass there with or without the mode; the first test fails on any CPU where the mode is not
in force, as MKL itself reports it.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest
import torch

from qdil import numerics

needs_mkl = pytest.mark.skipif(
    platform.machine() not in ("x86_64", "AMD64"), reason="torch uses MKL on x86 only"
)


def python(code: str, **env: str | None) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter with this environment changed by ``env``."""
    environ = {k: v for k, v in {**os.environ, **env}.items() if v is not None}
    return subprocess.run(
        [sys.executable, "-c", code], env=environ, capture_output=True, text=True, timeout=120
    )


@needs_mkl
def test_mkl_runs_in_a_strict_reproducible_mode_in_this_process() -> None:
    mode = numerics.mkl_mode()
    assert mode is not None, "torch's MKL service functions were not found"
    assert numerics.in_force(), f"MKL runs in mode {mode}, qdil asked for {numerics.requested()}"
    assert mode.endswith(",STRICT"), f"{mode}: without STRICT, products depend on thread count"


def test_a_product_gives_the_same_bits_on_one_and_two_threads() -> None:
    """The PPO update's largest products: MKL splits them among threads (Intel, non-STRICT)."""
    generator = torch.Generator().manual_seed(0)
    a = torch.randn(1, 256, 4096, generator=generator)
    b = torch.randn(1, 4096, 256, generator=generator)
    threads = torch.get_num_threads()
    try:
        results = []
        for count in (1, 2):
            torch.set_num_threads(count)
            results.append(torch.bmm(a, b))
    finally:
        torch.set_num_threads(threads)
    assert torch.equal(*results)


@needs_mkl
def test_processes_started_by_qdil_inherit_the_mode() -> None:
    code = (
        "import ctypes, os, torch\n"
        "lib = ctypes.CDLL(os.path.join(os.path.dirname(torch.__file__), 'lib', "
        "'libtorch_cpu.so'))\n"
        "torch.randn(64, 64) @ torch.randn(64, 64)\n"
        "print(lib.mkl_serv_cbwr_get(ctypes.c_int(~0)))\n"
    )
    done = python(code)  # no qdil import in the child: only the inherited variable
    assert done.returncode == 0, done.stderr
    assert numerics.name(int(done.stdout)) == numerics.mkl_mode()


@needs_mkl
def test_torch_computing_before_qdil_is_imported_is_warned() -> None:
    code = "import torch\ntorch.randn(64, 64) @ torch.randn(64, 64)\nimport qdil\n"
    late = python(code, MKL_CBWR=None)
    assert late.returncode == 0, late.stderr
    assert "ReproducibilityWarning" in late.stderr and "Import qdil before" in late.stderr
    early = python("import torch\nimport qdil\ntorch.randn(64, 64) @ torch.randn(64, 64)\n")
    assert early.returncode == 0 and "ReproducibilityWarning" not in early.stderr, early.stderr


def test_an_invalid_mode_is_refused_naming_the_variable() -> None:
    done = python("import qdil", MKL_CBWR="FASTEST")
    assert done.returncode != 0
    assert "MKL_CBWR='FASTEST' is not an MKL reproducibility mode" in done.stderr
    assert numerics.parse("avx2,strict") == numerics.parse("AVX2,STRICT") == 10 | numerics.STRICT


@needs_mkl
def test_a_worker_computing_otherwise_than_the_head_refuses() -> None:
    env = numerics.worker_env()
    numerics.require_env(env, "a worker")  # this process computes as it asks
    branch = "COMPATIBLE" if numerics.resolved_mode() != "COMPATIBLE,STRICT" else "SSE2"
    with pytest.raises(RuntimeError, match=f"in a worker, not {branch},STRICT"):
        numerics.require_env({**env, "MKL_CBWR": f"{branch},STRICT"}, "a worker")
    with pytest.raises(RuntimeError, match="ATEN_CPU_CAPABILITY"):
        numerics.require_env({**env, "ATEN_CPU_CAPABILITY": "vsx"}, "a worker")
