"""A finished run opened from Python: read-only, its elites act as the run scored them."""

from __future__ import annotations

import csv
import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

import qdil
from qdil.qd.checkpoint import load_archive
from qdil.recipe_load import RecipeError
from tests.commands import cli


def _fingerprint(folder: Path) -> dict[str, str]:
    return {
        str(path.relative_to(folder)): hashlib.sha256(path.read_bytes()).hexdigest()
        for path in sorted(folder.rglob("*"))
        if path.is_file()
    }


def test_an_elite_plays_its_episode_as_the_run_scored_it(smoke_run: Path, tmp_path: Path) -> None:
    before = _fingerprint(smoke_run)
    done = qdil.open_run(smoke_run)
    assert done.task == "Walker2d-v5"
    archive = done.archive("true")
    expected, iteration = load_archive(smoke_run, "true")
    assert done.iteration == iteration == 1
    assert archive.stats.qd_score == expected.stats.qd_score
    with open(smoke_run / "metrics.csv", newline="") as file:
        logged = list(csv.DictReader(file))
    assert [row["iteration"] for row in logged] == ["1"]
    assert done.metrics()[0]["qd/qd_score"] == float(logged[0]["qd/qd_score"])

    _, summary = done.rescore(episodes=1)
    assert summary["elites_evaluated"] == len(archive)

    elites = archive.data()
    best = int(np.argmax(elites["objective"]))
    cell = [int(i) for i in archive.int_to_grid_index([elites["index"][best]])[0]]
    (exported,) = done.export(tmp_path / "gaits", "onnx", cell=cell, episodes=1, seed=7)
    assert exported.path.is_file()
    (recorded,) = exported.metadata["episodes"]  # as qdil's engine played it

    policy = done.policy(cell)  # the best elite, named by its cell
    env = done.make_env(1)
    obs, _ = env.reset(seed=7)
    total, steps, finished = 0.0, 0, False
    while not finished:
        action = policy.act(obs[0])
        assert action.shape == env.single_action_space.shape
        obs, reward, terminated, truncated, _ = env.step(action[None])
        total, steps = total + float(reward[0]), steps + 1
        finished = bool(terminated[0] or truncated[0])
    assert steps == recorded["length"]
    # actions equal qdil's sampler to float32 rounding; the states follow their last bits
    assert total == pytest.approx(recorded["return"], rel=1e-2)
    assert np.array_equal(policy.act(obs), policy.act(obs[0])[None])
    assert len(done.policies(2)) == 2

    report = done.report(tmp_path / "report", records=False)
    assert (tmp_path / "report" / "report.md").is_file() and len(report.runs) == 1
    assert _fingerprint(smoke_run) == before, "opening a run must change nothing in it"


def test_the_same_figures_as_qdil_eval(smoke_run: Path, tmp_path: Path, capsys) -> None:
    """Re-scoring from Python returns what ``qdil eval`` writes into eval.json."""
    _, summary = qdil.open_run(smoke_run).rescore(episodes=2, seed=3)
    assert cli(["eval", str(smoke_run), "--episodes", "2", "--seed", "3"], capsys)[0] == 0
    written = json.loads((smoke_run / "eval.json").read_text())
    assert summary["metrics"] == written["metrics"]
    assert summary["qd_score_se"] == written["qd_score_se"]


def test_a_folder_without_a_run_and_an_unknown_archive_are_named(
    smoke_run: Path, tmp_path: Path
) -> None:
    with pytest.raises(RecipeError, match=f"{tmp_path} is not a qdil run directory"):
        qdil.open_run(tmp_path)
    with pytest.raises(ValueError, match="which must be one of true, deployable, got 'main'"):
        qdil.open_run(smoke_run).archive("main")
