"""``qdil sweep --search optuna``: ranges are checked before anything runs, every trial is
the plain ``qdil fit`` of its sampled options, trials are ranked by their re-scored archive,
a trial stopped early is pruned (never ranked by its training value), and a killed search
run again goes on where it stopped."""

from __future__ import annotations

import json
import os
import signal
import time

import pytest

pytest.importorskip("ray.tune")
pytest.importorskip("optuna")

import optuna
import ray

from qdil.cli import main
from qdil.sweeps.search import Domain, RescoredOptunaSearch, Search, parse_domain
from tests.cli.test_reproducible_runs import archives, metrics, same_archives
from tests.commands import SMOKE, start_qdil

SPACE = ["--space", "rl.init_args.learning_rate=log:1e-4:1e-2"]


@pytest.fixture(scope="module", autouse=True)
def _ray_down():
    yield
    if ray.is_initialized():
        ray.shutdown()


@pytest.mark.parametrize(
    ("spec", "domain"),
    [
        ("a.b=0.1:1", Domain("a.b", "uniform", (0.1, 1.0))),
        ("a.b=log:1e-4:1e-2", Domain("a.b", "log", (1e-4, 1e-2))),
        ("a.b=int:2:8", Domain("a.b", "int", (2, 8))),
        ("a.b=choice:x,y", Domain("a.b", "choice", ("x", "y"))),
    ],
)
def test_ranges_are_read_in_every_form(spec: str, domain: Domain) -> None:
    assert parse_domain(spec) == domain


@pytest.mark.parametrize(
    ("spec", "said"),
    [
        ("a.b", "KEY=LOW:HIGH"),
        ("a.b=1:x", "KEY=LOW:HIGH"),
        ("a.b=2:1", "low end must lie below"),
        ("a.b=log:0:1", "above 0 on a log scale"),
        ("a.b=choice:x", "two choices"),
    ],
)
def test_a_bad_range_is_refused_naming_it(spec: str, said: str) -> None:
    with pytest.raises(SystemExit, match=said):
        parse_domain(spec)


def test_a_range_end_the_recipe_refuses_stops_the_search_before_it_starts(tmp_path) -> None:
    root = tmp_path / "runs"
    command = ["sweep", str(SMOKE), "--seeds", "0", "--root", str(root), "--search", "optuna"]
    with pytest.raises(SystemExit, match="num_minibatches"):
        main([*command, "--space", "rl.init_args.num_minibatches=int:-3:2"])
    with pytest.raises(SystemExit, match="one recipe, one seed"):
        main([*command[:3], "0", "1", *command[4:], *SPACE])
    assert not root.exists()


def test_a_trial_stopped_early_is_pruned_not_ranked_by_its_training_value() -> None:
    from ray import tune

    searcher = RescoredOptunaSearch(space={"x": tune.uniform(0, 1)}, metric="objective", mode="max")
    for trial_id, result in (("a", {"objective": 0.9}), ("b", {"objective": 0.4, "rescored": 1})):
        searcher.suggest(trial_id)
        searcher.on_trial_result(trial_id, {"objective": 0.9, "training_iteration": 1})
        searcher.on_trial_complete(trial_id, result)
    stopped, scored = searcher._ot_study.trials
    assert stopped.state == optuna.trial.TrialState.PRUNED  # TPE ranks it below all complete
    assert scored.state == optuna.trial.TrialState.COMPLETE and scored.value == 0.4
    assert searcher._ot_study.best_trial.number == scored.number


def test_search_settings_stop_early_only_before_the_budget() -> None:
    config = Search((parse_domain("a=0:1"),), grace=1, iterations=3).tune_config()
    assert config.scheduler._max_t == 4  # the last iteration's row goes on to its re-scoring
    assert type(Search((parse_domain("a=0:1"),), grace=0).tune_config().scheduler).__name__ == (
        "FIFOScheduler"
    )


def _ranking(said: str) -> list[tuple[float, str, list[str]]]:
    lines = said.split("best first (also ", 1)[1].splitlines()[1:]
    rows = [line.split() for line in lines if line.startswith("  ")]
    return [(float(row[0]), row[1], row[2:]) for row in rows]


def test_a_killed_search_goes_on_and_each_trial_equals_its_plain_fit(
    tmp_path, monkeypatch, capsys
) -> None:
    """Killed (SIGKILL to its process group) once its first trial is re-scored, run again:
    it ends ranked by re-scored coverage, with no trial run twice, each as ``qdil fit``.
    (The killed search is a process of its own; what follows runs in this process.)"""
    root = tmp_path / "runs"
    command = ["sweep", str(SMOKE), "--seeds", "0"]
    command += ["--root", str(root), "--search", "optuna", *SPACE, "--samples", "2"]
    command += ["--grace", "0", "--episodes", "1", "--concurrent", "1"]
    search = start_qdil(*command, cwd=tmp_path)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and not list(root.glob("*/eval.json")):
        time.sleep(0.5)
    os.killpg(search.pid, signal.SIGKILL)
    search.wait()
    (first,) = root.glob("*/eval.json")  # one trial, one at a time, re-scored before the kill
    when = first.stat().st_mtime_ns
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("QDIL_PLUGIN_PATH", raising=False)
    monkeypatch.setenv("WANDB_MODE", "disabled")  # as tests.commands.user_env gives a process
    capsys.readouterr()
    main(command)
    assert first.stat().st_mtime_ns == when  # the finished trial was not run again
    ranked = _ranking(capsys.readouterr().err)
    assert len(ranked) == 2 and ranked[0][0] >= ranked[1][0]
    assert sorted(root.glob("walker_true-*-seed0")) == sorted(root / name for _, name, _ in ranked)
    for value, name, _ in ranked:
        summary = json.loads((root / name / "eval.json").read_text())
        assert summary["metrics"]["coverage"] == value
    (table,) = root.glob(".tune/*/ranking.csv")
    rows = table.read_text().splitlines()
    assert rows[0] == "run,coverage,rl.init_args.learning_rate" and len(rows) == 3
    _, name, options = ranked[-1]
    main(["fit", str(SMOKE), "--seed", "0", *options, "--logging.root", "plain"])
    trial, alone = root / name, tmp_path / "plain" / "walker_true-seed0"
    assert metrics(trial) == metrics(alone)
    assert same_archives(archives(trial), archives(alone))
