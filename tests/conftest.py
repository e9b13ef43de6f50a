"""Shared test settings (single-threaded torch, quiet W&B, fixed seeds) and shared fixtures:
the test's own demonstrations, an OpenGL backend, a one-iteration smoke run."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

os.environ.setdefault("WANDB_MODE", "disabled")
# one physics thread per test process: tests check results, not speed, and several
# processes on few cores must not oversubscribe numba's thread pool
os.environ.setdefault("QDIL_NUM_THREADS", "1")
os.environ.setdefault("WANDB_SILENT", "true")

import numba
import numpy as np
import pytest
import torch


@numba.njit(parallel=True)
def _parallel_sum(x: np.ndarray) -> float:  # pragma: no cover - numba
    total = 0.0
    for i in numba.prange(x.shape[0]):
        total += x[i]
    return total


# numba's OpenMP pool, when it first runs a parallel kernel, sets the OpenMP thread count that
# torch shares to every core; torch's reductions over many numbers split by that count. Start
# the pool now, so that no test's numbers depend on whether an earlier test stepped physics.
_parallel_sum(np.ones(64))
torch.set_num_threads(1)


@pytest.fixture(autouse=True)
def one_torch_thread() -> None:
    """Every test starts with one torch thread (in-process workers set their own)."""
    torch.set_num_threads(1)


def _at_threads(threads: int, fn: Callable[[], Any]) -> Any:
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        return fn()
    finally:
        torch.set_num_threads(before)


@pytest.fixture
def at_threads() -> Callable[[int, Callable[[], Any]], Any]:
    """``at_threads(n, fn)``: ``fn()`` computed with n torch threads (the count restored)."""
    return _at_threads


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture(scope="session")
def walker_demos(tmp_path_factory: pytest.TempPathFactory):
    """A small Walker2d demonstration file the tests make themselves (two short episodes)."""
    from qdil.demos.generate import record_episodes
    from qdil.demos.io import save_demos
    from qdil.rl.networks import VectorizedActor
    from qdil.rl.normalize import RunningMeanStd

    solutions = np.stack([VectorizedActor.initial_solution(17, 6, seed=s) for s in (0, 1)])
    demos, qpos, qvel = record_episodes(
        "Walker2d-v5", solutions, RunningMeanStd(2, (17,)), seed=3, max_episode_steps=60
    )
    path = tmp_path_factory.mktemp("demos") / "walker_tiny.npz"
    save_demos(demos, path, qpos, qvel)
    return path


"""PPGA on the true reward at the sizes of a test: a few seconds an iteration."""


@pytest.fixture(scope="module")
def gl() -> str:
    """The OpenGL backend, or a skip that says why none renders here."""
    from qdil.envs.gl import GLUnavailableError, use_gl_backend

    try:
        return use_gl_backend()
    except GLUnavailableError as error:
        pytest.skip(f"no OpenGL backend renders here: {error}")


@pytest.fixture(scope="session")
def _smoke_made(tmp_path_factory: pytest.TempPathFactory, worker_id: str) -> Path:
    """The one-iteration smoke run, trained once per test session (in this process, by the
    first worker to get here; the others wait for it and read the same folder)."""
    from filelock import FileLock

    # xdist's workers share the parent of their base folders; a lone run has its own
    shared = tmp_path_factory.getbasetemp()
    shared = shared.parent if worker_id != "master" else shared
    root = shared / "smoke-run"
    with FileLock(str(shared / "smoke-run.lock")):
        if not (root / "runs" / "tiny" / "config.yaml").is_file():
            from tests.commands import SMOKE, qdil_here  # qdil imported after the variables

            root.mkdir(exist_ok=True)
            qdil_here(["fit", str(SMOKE), "--qd.iterations", "1", "--name", "tiny"], root)
    return root / "runs" / "tiny"


@pytest.fixture(scope="module")
def smoke_run(_smoke_made: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A one-iteration run of the smoke recipe with a checkpoint (no plugins, no W&B): a
    copy of the session's, which the module may write into."""
    import shutil

    copy = tmp_path_factory.mktemp("smoke") / "runs" / "tiny"
    shutil.copytree(_smoke_made, copy)
    return copy
