"""Sharding the simulations among workers changes no bit (checked in-process, without Ray)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch
from executor_helpers import InProcessExecutor, make_vppo, run_phases, same_outputs

from qdil.executors.shards import shard_bounds
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd


@pytest.mark.parametrize("workers", [1, 2, 3, 5])
def test_sharded_runs_equal_the_local_run(workers, local_outputs) -> None:
    executor = InProcessExecutor(num_workers=workers)
    got = run_phases(executor)
    assert len(executor.bounds) > 1 or workers == 1
    assert same_outputs(local_outputs, got)


def test_a_local_run_repeated_in_one_process_gives_the_same_bits(local_outputs) -> None:
    """After other allocations and with another torch thread count (MKL's CNR mode, STRICT)."""
    kept = [torch.empty(7 * k + 1) for k in range(1, 300)]  # the allocator's state moves on
    threads = torch.get_num_threads()
    torch.set_num_threads(2 if threads == 1 else 1)
    try:
        again = run_phases(None)
    finally:
        torch.set_num_threads(threads)
    assert kept and same_outputs(local_outputs, again)


def test_the_walk_gives_the_same_bits_with_one_and_two_threads(at_threads) -> None:
    """Noise seed 4 made the walk's critic clip its 256 x 256 layer differently on 2 threads."""

    def walk() -> list:
        algo, _ = make_vppo(None)
        algo.generator.manual_seed(4)
        theta = VectorizedActor.initial_solution(17, 6, (128, 128), 0)
        stats = RunningMeanStd(1, (17,))
        phase = algo.walk(theta, stats, np.array([1.0, 0.5, -0.5]), lambda r: r.rewards, 2)
        return [phase.solutions, phase.stats.mean, phase.stats.var, phase.diagnostics]

    assert same_outputs(at_threads(1, walk), at_threads(2, walk))


@pytest.mark.parametrize("num_envs", [6, 3])
def test_small_batches_are_cut_anywhere(num_envs: int) -> None:
    """6 simulations on 2 workers cut policy 1's block of 2 in half; 3 give blocks of 1."""
    local = run_phases(None, num_envs)
    executor = InProcessExecutor(num_workers=2)
    got = run_phases(executor, num_envs)
    assert len(executor.bounds) == 2
    assert same_outputs(local, got)


def test_more_workers_than_simulations_run_one_shard_each() -> None:
    local = run_phases(None, 6)
    executor = InProcessExecutor(num_workers=7)
    with pytest.warns(UserWarning, match="7 asked"):
        got = run_phases(executor, 6)
    assert len(executor.workers) == len(executor.bounds) == 6
    assert same_outputs(local, got)


@pytest.mark.parametrize(("n", "shards"), [(12, 2), (12, 5), (6, 2), (3000, 16), (64, 7), (3, 5)])
def test_shards_cover_the_batch_in_near_equal_parts(n, shards) -> None:
    bounds = shard_bounds(n, shards)
    assert bounds[0][0] == 0 and bounds[-1][1] == n and len(bounds) == min(n, shards)
    assert all(x[1] == y[0] for x, y in itertools.pairwise(bounds))
    sizes = [b - a for a, b in bounds]
    assert min(sizes) >= 1 and max(sizes) - min(sizes) <= 1
