"""Sharding the simulations among workers changes no bit (checked in-process, without Ray)."""

from __future__ import annotations

import itertools

import pytest
from executor_helpers import InProcessExecutor, run_phases, same_outputs

from qdil.executors.shards import MIN_ROWS, shard_bounds


@pytest.mark.parametrize("workers", [1, 2, 3, 5])
def test_sharded_runs_equal_the_local_run(workers, local_outputs) -> None:
    executor = InProcessExecutor(num_workers=workers)
    got = run_phases(executor)
    assert len(executor.bounds) > 1 or workers == 1
    assert same_outputs(local_outputs, got)


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
