"""The physics kernels are cached on disk: a second process loads them instead of compiling."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

STEP = """
from qdil.envs.physics import _step_kernel
from qdil.envs.vector import LocomotionVectorEnv

LocomotionVectorEnv("Walker2d-v5", 2, num_threads=1).reset(seed=0)  # one kernel launch
print(_step_kernel.stats.cache_hits.total(), _step_kernel.stats.cache_misses.total())
"""


def step_once(cache: Path) -> tuple[list[int], str]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    done = subprocess.run(
        [sys.executable, "-c", STEP], env=env, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return [int(n) for n in done.stdout.split()], done.stderr


def test_a_second_process_loads_the_kernels_from_the_cache(tmp_path: Path) -> None:
    first, stderr = step_once(tmp_path)
    assert first == [0, 1], "the first process compiles"
    assert "Cannot cache" not in stderr, stderr  # no address baked into the kernels
    assert any(tmp_path.rglob("physics._step_kernel-*.nbi"))
    second, _ = step_once(tmp_path)
    assert second == [1, 0], "the second process loads the compiled kernel"


def test_without_a_writable_cache_folder_the_kernels_compile_as_before(monkeypatch) -> None:
    import numba.core.caching as caching

    from qdil.envs.mujoco_c import cached_njit

    monkeypatch.setattr(caching.CacheImpl, "_locator_classes", [])  # nowhere to write

    @cached_njit()
    def plus_one(x):  # pragma: no cover - numba
        return x + 1

    assert plus_one(1) == 2
