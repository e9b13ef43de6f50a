from __future__ import annotations

import warnings

import numpy as np
import pytest
from ribs.schedulers import Scheduler

from qdil.qd.archives import elite_fields, make_grid
from qdil.qd.emitter import PPGAEmitter, resolve_es
from qdil.qd.xnes import XNES

DIM, OBS = 12, 3


def fields(n: int, value: float = 0.0) -> dict[str, np.ndarray]:
    return {
        "obs_mean": np.full((n, OBS), value),
        "obs_var": np.ones((n, OBS)),
        "obs_count": np.full(n, 1.0 + value),
        "length": np.full(n, 100.0),
    }


@pytest.fixture
def archive():
    return make_grid(
        solution_dim=DIM,
        cells=[5, 5],
        extra_fields=elite_fields(OBS),
        learning_rate=0.5,
        threshold_min=0.0,
        seed=0,
    )


def make_emitter(archive, **kwargs) -> PPGAEmitter:
    return PPGAEmitter(archive, np.zeros(DIM), batch_size=8, sigma0=0.5, seed=1, **kwargs)


def test_jacobian_rows_are_normalised_and_branches_follow_the_coefficients(archive) -> None:
    emitter = make_emitter(archive)
    assert emitter.ask_dqd().shape == (1, DIM)
    jacobian = np.zeros((1, 3, DIM))
    jacobian[0, 0, 0], jacobian[0, 1, 1], jacobian[0, 2, :2] = 5.0, -0.1, [3.0, 4.0]
    emitter.tell_dqd(
        np.zeros((1, DIM)),
        np.zeros(1),
        np.zeros((1, 2)),
        jacobian,
        {"status": np.ones(1), "value": np.ones(1)},
    )
    branches = emitter.ask()
    assert branches.shape == (8, DIM)
    unit = np.zeros((3, DIM))
    unit[0, 0], unit[1, 1], unit[2, :2] = 1.0, -1.0, [0.6, 0.8]
    np.testing.assert_allclose(branches, emitter.coefficients @ unit, rtol=1e-5, atol=1e-6)


def test_initial_mean_follows_ppga_bounds(archive) -> None:
    for seed in range(20):
        mean = PPGAEmitter(archive, np.zeros(DIM), batch_size=4, seed=seed).coefficient_mean
        assert 0 <= mean[0] <= 2 and np.all(np.abs(mean[1:]) <= 2)
    zero = make_emitter(archive, initial_mean="zero").coefficient_mean
    np.testing.assert_array_equal(zero, 0.0)


def tell_round(emitter, archive, status: np.ndarray) -> np.ndarray:
    emitter.tell_dqd(
        np.zeros((1, DIM)),
        np.zeros(1),
        np.zeros((1, 2)),
        np.ones((1, 3, DIM)),
        {"status": np.ones(1), "value": np.ones(1)},
    )
    branches = emitter.ask()
    values = np.linspace(1, -1, len(branches))
    emitter.tell(
        branches,
        np.ones(len(branches)),
        np.full((len(branches), 2), 0.5),
        {"status": status, "value": values},
        **fields(len(branches)),
    )
    return branches


def test_no_improvement_restarts_at_a_random_elite_with_its_own_statistics(archive) -> None:
    elite = np.arange(DIM, dtype=np.float32)
    archive.add(elite[None], np.array([10.0]), np.array([[0.9, 0.1]]), **fields(1, value=7.0))
    emitter = make_emitter(archive)
    tell_round(emitter, archive, status=np.zeros(8))
    assert emitter.restarts == 1
    np.testing.assert_array_equal(emitter.theta, elite)
    np.testing.assert_array_equal(emitter.theta_fields["obs_mean"], np.full(OBS, 7.0))
    assert emitter.theta_fields["obs_count"] == 8.0
    assert emitter.es.sigma == 0.5  # fresh strategy


def test_improvement_adapts_the_strategy_without_restarting(archive) -> None:
    emitter = make_emitter(archive)
    before = emitter.coefficient_mean
    tell_round(emitter, archive, status=np.r_[np.ones(2), np.zeros(6)])
    assert emitter.restarts == 0 and emitter.last_improved == 2
    assert not np.allclose(emitter.coefficient_mean, before)


def test_restart_with_an_empty_archive_keeps_theta(archive) -> None:
    emitter = make_emitter(archive)
    emitter.move(np.ones(DIM), emitter.theta_fields)
    tell_round(emitter, archive, status=np.zeros(8))
    assert emitter.restarts == 1
    np.testing.assert_array_equal(emitter.theta, 1.0)


def test_works_inside_a_pyribs_scheduler(archive) -> None:
    emitter = make_emitter(archive)
    scheduler = Scheduler(archive, [emitter], add_mode="batch")
    rng = np.random.default_rng(0)
    for _ in range(3):
        theta = scheduler.ask_dqd()
        scheduler.tell_dqd(
            np.array([5.0]), np.array([[0.5, 0.5]]), rng.normal(size=(1, 3, DIM)), **fields(1)
        )
        branches = scheduler.ask()
        scheduler.tell(
            rng.uniform(0, 10, len(branches)),
            rng.uniform(0, 1, (len(branches), 2)),
            **fields(len(branches)),
        )
        emitter.move(theta[0] + 0.1, emitter.theta_fields)
    assert len(archive) > 5


def test_the_loop_silences_only_the_empty_archive_warning() -> None:
    """A θ_μ below threshold_min leaves the archive empty: expected, so not shouted about."""
    from qdil.qd.loop import quiet_empty_archive

    high = make_grid(
        solution_dim=DIM,
        cells=[5, 5],
        extra_fields=elite_fields(OBS),
        learning_rate=0.5,
        threshold_min=200.0,
    )
    scheduler = Scheduler(high, [make_emitter(high)], add_mode="batch")
    jacobian = np.zeros((1, 3, DIM))
    scheduler.ask_dqd()
    with pytest.warns(UserWarning, match="threshold_min"):  # pyribs' own, outside the loop
        scheduler.tell_dqd(np.array([5.0]), np.array([[0.5, 0.5]]), jacobian, **fields(1))
    scheduler.ask_dqd()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any other warning still surfaces
        with quiet_empty_archive():
            scheduler.tell_dqd(np.array([5.0]), np.array([[0.5, 0.5]]), jacobian, **fields(1))
    assert high.empty


def test_strategies_resolve_by_name_or_path() -> None:
    assert resolve_es("xnes") is XNES
    assert resolve_es("qdil.qd.xnes.XNES") is XNES
    assert resolve_es("cma_es").__name__ == "CMAEvolutionStrategy"
    with pytest.raises(ValueError, match="unknown evolution strategy 'nes'; use one of xnes"):
        resolve_es("nes")
    with pytest.raises(ValueError, match="not a ribs EvolutionStrategyBase"):
        resolve_es("numpy.ndarray")


def test_cma_es_is_selectable(archive) -> None:
    emitter = make_emitter(archive, es="cma_es")
    tell_round(emitter, archive, status=np.r_[np.ones(3), np.zeros(5)])
    assert emitter.coefficient_mean.shape == (3,)


def test_proposed_branches_are_what_ask_returns_and_change_nothing_else() -> None:
    """Proposing before ``tell_dqd`` (to score θ_μ and branches in one batch) is invisible.

    Two schedulers from the same seeds, one asked the plain way and one proposing first,
    give the same branches and end in the same archive and strategy over several rounds.
    """
    rng = np.random.default_rng(0)
    plan = [(rng.normal(size=(1, 3, DIM)), rng.uniform(0, 10, 8), rng.uniform(0, 1, (8, 2)))]
    plan *= 3
    results = []
    for propose in (False, True):
        grid = make_grid(
            solution_dim=DIM,
            cells=[5, 5],
            extra_fields=elite_fields(OBS),
            learning_rate=0.5,
            threshold_min=0.0,
            seed=0,
        )
        emitter = make_emitter(grid)
        scheduler = Scheduler(grid, [emitter], add_mode="batch")
        asked = []
        for jacobian, objective, measures in plan:
            scheduler.ask_dqd()
            proposed = emitter.propose(jacobian) if propose else None
            scheduler.tell_dqd(np.array([5.0]), np.array([[0.5, 0.5]]), jacobian, **fields(1))
            branches = scheduler.ask()
            if proposed is not None:
                np.testing.assert_array_equal(branches, proposed)
            asked.append(branches)
            scheduler.tell(objective, measures, **fields(len(branches)))
        results.append((asked, grid.data("objective"), emitter.coefficient_mean))
    (plain, plain_objective, plain_mean), (batched, batched_objective, batched_mean) = results
    for a, b in zip(plain, batched, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(np.sort(plain_objective), np.sort(batched_objective))
    np.testing.assert_array_equal(plain_mean, batched_mean)
