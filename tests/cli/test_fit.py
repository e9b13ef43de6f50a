"""``qdil fit`` through the real command line: smoke run, recipe errors, kill and resume."""

from __future__ import annotations

import csv
import pickle
import signal
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from qdil.cli import main
from tests.commands import SMOKE, cli, qdil, start_qdil


def rows(run_dir: Path) -> list[dict[str, str]]:
    with open(run_dir / "metrics.csv", newline="") as file:
        return list(csv.DictReader(file))


def final_archive(run_dir: Path) -> dict[str, np.ndarray]:
    state = torch.load(run_dir / "checkpoints" / "last.pt", weights_only=False)
    return pickle.loads(state["true_archive"]).data()


def test_smoke_fit_writes_config_metrics_and_checkpoint(tmp_path: Path, monkeypatch) -> None:
    """The run is made in this process; the refused second one is a process (its exit status
    and its message on stderr are the subject)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("QDIL_PLUGIN_PATH", raising=False)
    main(["fit", str(SMOKE), "--name", "smoke"])
    run_dir = tmp_path / "runs" / "smoke"
    config = (run_dir / "config.yaml").read_text()
    assert "class_path: qdil.rewards.builtin.TrueReward" in config
    assert "rollout_length: 16" in config and "sigma0: 1.0" in config  # resolved defaults
    metrics = rows(run_dir)
    assert [int(r["iteration"]) for r in metrics] == [1, 2, 3]
    assert float(metrics[-1]["qd/num_elites"]) >= 3
    assert float(metrics[-1]["perf/env_steps"]) > float(metrics[0]["perf/env_steps"])
    assert (run_dir / "checkpoints" / "last.pt").exists()
    again = qdil("fit", str(SMOKE), "--name", "smoke", cwd=tmp_path)
    assert again.returncode != 0 and "qdil fit --resume" in again.stderr


@pytest.mark.parametrize(
    ("override", "message"),
    [
        (["--qd.fitness", "best"], "qd.fitness"),
        (["--qd.itrations", "5"], "itrations"),
        (["--reward", "gial"], "unknown reward model 'gial'; registered: "),
        (["--env.task", "Walker3d-v5"], "known tasks: Walker2d-v5"),
        (["--env.num_env", "3"], "unknown key 'env.num_env' in --env.num_env; did you mean"),
        (["--qd.archive.typ", "cvt"], "unrecognized arguments: --qd.archive.typ"),  # no prefix
    ],
)
def test_bad_recipes_name_the_key(
    tmp_path: Path, override: list[str], message: str, capsys, monkeypatch
) -> None:
    """The message is the subject: checked in this process (the exit status as the console
    script gives it); the process's own exit status is test_smoke_fit's."""
    monkeypatch.chdir(tmp_path)
    code, _, err = cli(["fit", str(SMOKE), *override], capsys)
    assert code != 0
    assert message in err
    assert not (tmp_path / "runs").exists()  # no run folder left behind, nor its root


def test_killed_run_resumes_to_the_same_archive(tmp_path: Path) -> None:
    """SIGKILL mid-iteration after a checkpoint; the resumed run equals an unbroken one."""
    args = ["--qd.iterations", "4", "--logging.checkpoint_every", "2"]
    qdil("fit", str(SMOKE), *args, "--name", "unbroken", cwd=tmp_path, check=True)

    process = start_qdil("fit", str(SMOKE), *args, "--name", "killed", cwd=tmp_path)
    checkpoint = tmp_path / "runs" / "killed" / "checkpoints" / "last.pt"
    deadline = time.time() + 300
    while not checkpoint.exists() and process.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    process.send_signal(signal.SIGKILL)
    process.wait()
    assert process.returncode == -signal.SIGKILL, "the run must be killed, not finish"
    assert torch.load(checkpoint, weights_only=False)["iteration"] == 2

    qdil("fit", "--resume", str(tmp_path / "runs" / "killed"), cwd=tmp_path, check=True)
    unbroken, resumed = tmp_path / "runs" / "unbroken", tmp_path / "runs" / "killed"
    assert [r["iteration"] for r in rows(resumed)] == ["1", "2", "3", "4"]
    for a, b in zip(rows(unbroken), rows(resumed), strict=True):
        for key in ("qd/qd_score", "qd/coverage", "search/true_objective", "emitter/coefficient_0"):
            assert a[key] == b[key], key
    expected, actual = final_archive(unbroken), final_archive(resumed)
    order_e, order_a = np.argsort(expected["index"]), np.argsort(actual["index"])
    for field in ("index", "objective", "measures", "solution", "obs_mean"):
        np.testing.assert_array_equal(expected[field][order_e], actual[field][order_a])


def test_resume_of_a_directory_without_a_run_is_refused(tmp_path: Path, capsys) -> None:
    code, _, err = cli(["fit", "--resume", str(tmp_path)], capsys)
    assert code != 0 and "not a qdil run directory" in err


def test_bad_checkpoints_are_reported_with_the_file(tmp_path: Path, monkeypatch, capsys) -> None:
    """The messages are the subject: the run and its resumes run in this process, and an
    error that is not the user's would raise here instead of printing a message."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("QDIL_PLUGIN_PATH", raising=False)
    main(["fit", str(SMOKE), "--name", "ck", "--qd.iterations", "2"])
    run_dir = tmp_path / "runs" / "ck"
    checkpoint = run_dir / "checkpoints" / "last.pt"
    config = (run_dir / "config.yaml").read_text()
    (run_dir / "config.yaml").write_text(config.replace("task: Walker2d-v5", "task: Hopper-v5"))
    code, _, err = cli(["fit", "--resume", str(run_dir)], capsys)
    # the checkpoint stores its recipe: the edited key is named before anything is built
    assert code != 0 and "env.task: 'Walker2d-v5' -> 'Hopper-v5'" in err
    (run_dir / "config.yaml").write_text(config)
    checkpoint.write_bytes(checkpoint.read_bytes()[:1000])
    code, _, err = cli(["fit", "--resume", str(run_dir)], capsys)
    assert code != 0
    assert f"{checkpoint} is not a readable qdil checkpoint" in err
    assert "Traceback" not in err


def test_a_recipe_of_an_older_run_with_a_moved_class_still_parses(tmp_path: Path) -> None:
    """Run directories written before the executors moved name the old class path."""
    import yaml

    from qdil.cli.fit import fit_parser, parse_fit
    from qdil.executors import LocalExecutor

    recipe = yaml.safe_load(SMOKE.read_text())
    recipe["executor"] = {"class_path": "qdil.rl.execution.LocalExecutor"}
    (tmp_path / "old.yaml").write_text(yaml.safe_dump(recipe))
    config, _, _ = parse_fit([str(tmp_path / "old.yaml")])
    assert isinstance(fit_parser().instantiate(config).executor, LocalExecutor)


def test_a_switch_of_reward_model_leaves_the_recipes_form_behind() -> None:
    """``--reward gail`` on WQDIL's recipe trains GAIL with GAIL's form, not the critic's,
    and keeps the recipe's shared options (a fall's absorbing state, the inputs' clip)."""
    from qdil.cli.fit import parse_fit

    flagship = str(Path(__file__).resolve().parents[2] / "recipes" / "walker_mcwae.yaml")
    kept = parse_fit([flagship])[0].reward.init_args
    assert kept.reward_form == "standardized_logit" and kept.batch_size == 120
    switched = parse_fit([flagship, "--reward", "gail"])[0].reward.init_args
    assert switched.reward_form is None and switched.batch_size == 120  # GAIL's log1-d
    assert (switched.absorbing, switched.feature_clip) == ("floor", 10.0)
    chosen = parse_fit([flagship, "--reward=gail", "--reward.reward_form", "calibrated"])[0]
    assert chosen.reward.init_args.reward_form == "calibrated"


def test_absorbing_true_of_an_older_run_reads_as_learned() -> None:
    """Runs of the first absorbing option stored ``absorbing: true`` (DAC's learned state)."""
    from qdil.upgrades import upgraded

    old = {"reward": {"class_path": "gail", "init_args": {"absorbing": True}}}
    assert upgraded(old)["reward"]["init_args"]["absorbing"] == "learned"
    assert old["reward"]["init_args"]["absorbing"] is True  # the caller's copy is kept
    assert upgraded({"reward": {"init_args": {"absorbing": False}}})["reward"]["init_args"] == {
        "absorbing": None
    }
    for value in ("floor", None, 1):  # today's values, and what is not a bool, unchanged
        kept = upgraded({"reward": {"init_args": {"absorbing": value}}})
        assert kept["reward"]["init_args"]["absorbing"] == value
