"""Sharding the simulations among workers changes no bit (checked in-process, without Ray)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import torch
from executor_helpers import InProcessExecutor, make_vppo, run_phases, same_outputs

from qdil.executors.shards import MIN_ROWS, shard_bounds
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
        algo = make_vppo(None)
        algo.generator.manual_seed(4)
        theta, stats = algo.initial_solution(0), RunningMeanStd(1, (17,))
        phase = algo.walk(theta, stats, np.array([1.0, 0.5, -0.5]), lambda r: r.rewards, 2)
        return [phase.solutions, phase.stats.mean, phase.stats.var, phase.diagnostics]

    assert same_outputs(at_threads(1, walk), at_threads(2, walk))


@pytest.mark.parametrize(("num_envs", "workers"), [(6, 2), (6, 7), (3, 2)])
def test_small_batches_run_on_any_number_of_workers(num_envs: int, workers: int) -> None:
    """Fewer training shards than workers (6 simulations make one); evaluations follow."""
    local = run_phases(None, num_envs)
    executor = InProcessExecutor(num_workers=workers)
    with pytest.warns(UserWarning, match=f"{workers} asked"):
        got = run_phases(executor, num_envs)
    assert len(executor.workers) == len(executor.bounds) < workers
    assert same_outputs(local, got)


@pytest.mark.parametrize(
    ("n", "block", "shards"), [(12, 4, 2), (12, 4, 5), (6, 2, 2), (3000, 1000, 16), (64, 1, 7)]
)
def test_shards_cover_the_batch_and_cut_no_policy_too_thin(n, block, shards) -> None:
    bounds = shard_bounds(n, block, shards)
    assert bounds[0][0] == 0 and bounds[-1][1] == n and len(bounds) <= shards
    assert all(a < b for a, b in bounds)
    assert all(x[1] == y[0] for x, y in itertools.pairwise(bounds))
    for _, cut in bounds[:-1]:
        inside = cut % block
        assert inside == 0 or MIN_ROWS <= inside <= block - MIN_ROWS


def test_training_shards_are_large_enough_for_the_one_policy_walk() -> None:
    assert all(b - a >= MIN_ROWS for a, b in shard_bounds(12, 4, 5, MIN_ROWS))
    assert shard_bounds(6, 2, 2, MIN_ROWS) == [(0, 6)]
