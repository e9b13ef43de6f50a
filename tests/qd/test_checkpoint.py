from __future__ import annotations

import pickle

import numpy as np
from ribs.schedulers import Scheduler

from qdil.qd.archives import elite_fields, make_grid
from qdil.qd.checkpoint import dumps_compact
from qdil.qd.emitter import PPGAEmitter

DIM, OBS = 400, 3


def batch(rng: np.random.Generator, n: int) -> tuple:
    fields = {
        "obs_mean": rng.normal(size=(n, OBS)),
        "obs_var": rng.uniform(0.5, 2.0, (n, OBS)),
        "obs_count": rng.uniform(1, 100, n),
        "length": rng.integers(1, 1000, n).astype(float),
    }
    return rng.normal(size=(n, DIM)), rng.normal(1.0, 2.0, n), rng.uniform(0, 1, (n, 2)), fields


def test_compact_pickle_keeps_only_occupied_cells_and_behaves_identically() -> None:
    """A CMA-MAE archive round-tripped compactly equals the original, now and after adds."""
    rng = np.random.default_rng(0)
    archive = make_grid(
        solution_dim=DIM,
        cells=[10, 10],
        extra_fields=elite_fields(OBS),
        learning_rate=0.5,
        threshold_min=0.0,
        seed=0,
    )
    solutions, objectives, measures, fields = batch(rng, 30)
    archive.add(solutions, objectives, measures, **fields)
    assert 0 < len(archive) < 40  # most of the 100 cells are empty

    full, compact = pickle.dumps(archive), dumps_compact(archive)
    assert len(compact) < 0.5 * len(full)
    restored = pickle.loads(compact)

    before, after = archive.data(), restored.data()
    assert before.keys() == after.keys()
    for name in before:
        np.testing.assert_array_equal(before[name], after[name], err_msg=name)
    assert restored.stats == archive.stats

    # New cells take threshold_min and occupied cells their thresholds: inserts must agree.
    solutions, objectives, measures, fields = batch(rng, 200)
    added = archive.add(solutions, objectives, measures, **fields)
    added_restored = restored.add(solutions, objectives, measures, **fields)
    np.testing.assert_array_equal(added["status"], added_restored["status"])
    np.testing.assert_array_equal(added["value"], added_restored["value"])
    for name, values in archive.data().items():
        np.testing.assert_array_equal(values, restored.data()[name], err_msg=name)


def test_compact_pickle_keeps_shared_archives_shared() -> None:
    """The scheduler and its emitter point at one archive before and after the round trip."""
    archive = make_grid(
        solution_dim=DIM, cells=[5, 5], extra_fields=elite_fields(OBS), threshold_min=0.0, seed=0
    )
    emitter = PPGAEmitter(archive, np.zeros(DIM), batch_size=4, sigma0=0.5, seed=1)
    scheduler = pickle.loads(dumps_compact(Scheduler(archive, [emitter], add_mode="batch")))
    assert scheduler.emitters[0].archive is scheduler.archive
    assert len(scheduler.archive) == 0
