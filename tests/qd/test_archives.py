"""The passive archives: the true-keyed one and the deployable one keep different elites."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from qdil.qd.archives import (
    RunArchives,
    deployable_fields,
    elite_fields,
    make_grid,
    true_keyed,
)


def archives() -> RunArchives:
    grid = {"solution_dim": 3, "cells": [2, 2]}
    return RunArchives(
        main=make_grid(**grid, extra_fields=elite_fields(2)),
        true=make_grid(**grid, extra_fields=elite_fields(2)),
        deployable=make_grid(**grid, extra_fields=deployable_fields(2)),
    )


def fields(n: int) -> dict[str, np.ndarray]:
    return {
        "obs_mean": np.arange(2 * n, dtype=np.float64).reshape(n, 2),
        "obs_var": np.ones((n, 2)),
        "obs_count": np.full(n, 5.0),
        "length": np.full(n, 100.0),
    }


def test_each_archive_keeps_its_own_best_and_the_deployable_one_its_true_return() -> None:
    run = archives()
    solutions = np.array([[1.0, 0, 0], [2.0, 0, 0]], dtype=np.float32)
    measures = np.array([[0.1, 0.1], [0.2, 0.2]])  # one cell
    # policy 1 scores higher under the learned objective, policy 2 under the true return
    run.add(solutions, np.array([5.0, 1.0]), np.array([10.0, 20.0]), measures, fields(2))
    true, deployable = run.true.data(), run.deployable.data()
    assert true["solution"][:, 0].tolist() == [2.0] and true["objective"].tolist() == [20.0]
    assert deployable["solution"][:, 0].tolist() == [1.0]
    assert deployable["objective"].tolist() == [5.0]
    assert deployable["true_return"].tolist() == [10.0]
    assert deployable["obs_mean"].tolist() == [[0.0, 1.0]]  # its own statistics
    keyed = true_keyed(run.deployable).data()
    assert keyed["objective"].tolist() == [10.0] and keyed["solution"][:, 0].tolist() == [1.0]


def test_with_true_fitness_the_deployable_archive_ranks_by_the_true_return(
    walker_demos: Path, tmp_path: Path, monkeypatch
) -> None:
    from qdil.cli import main
    from qdil.qd.checkpoint import load_archive

    monkeypatch.chdir(tmp_path)
    recipe = Path(__file__).resolve().parents[2] / "recipes" / "smoke" / "walker_il.yaml"
    args = ["--demos.path", str(walker_demos), "--qd.fitness", "true", "--qd.iterations", "1"]
    main(["fit", str(recipe), *args, "--name", "oracle"])
    deployable, _ = load_archive(tmp_path / "runs" / "oracle", "deployable")
    data = deployable.data()
    assert len(data["objective"]) > 0
    assert np.array_equal(data["objective"], data["true_return"])


def test_an_oracle_runs_deployable_archive_is_scored_once_with_the_same_result(
    walker_demos: Path, tmp_path: Path, monkeypatch
) -> None:
    from qdil.cli import main
    from qdil.evaluation.rescore import rescore, rescore_archive

    monkeypatch.chdir(tmp_path)
    recipe = Path(__file__).resolve().parents[2] / "recipes" / "smoke" / "walker_il.yaml"
    args = ["--demos.path", str(walker_demos), "--qd.fitness", "true", "--qd.iterations", "1"]
    main(["fit", str(recipe), *args, "--name", "oracle"])
    run_dir = tmp_path / "runs" / "oracle"
    _, summary = rescore_archive(run_dir, episodes=1, num_threads=1)
    assert summary["deployable"]["same_as_true"] is True
    # what playing the deployable archive's own episodes gives
    _, played = rescore(run_dir, "deployable", episodes=1, num_threads=1)
    assert summary["deployable"]["metrics"] == played["metrics"]
    assert summary["deployable"]["qd_score_se"] == played["qd_score_se"]
    assert summary["deployable"]["learned_metrics"] == played["learned_metrics"]
    assert summary["deployable"]["training_metrics"] == played["training_metrics"]


def test_archives_with_other_elites_are_not_the_same() -> None:
    from qdil.evaluation.rescore import same_elites

    run = archives()
    solutions = np.array([[1.0, 0, 0], [2.0, 0, 0]], dtype=np.float32)
    measures = np.array([[0.1, 0.1], [0.2, 0.2]])  # one cell
    run.add(solutions, np.array([5.0, 1.0]), np.array([10.0, 20.0]), measures, fields(2))
    assert not same_elites(run.true, run.deployable)
    assert same_elites(run.true, run.true)
