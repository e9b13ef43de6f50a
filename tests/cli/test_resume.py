"""``qdil fit --resume`` through the real command line: a run directory is never stuck, and a
resume whose config.yaml was edited since its checkpoint is refused, naming the keys."""

from __future__ import annotations

import csv
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
import yaml

from qdil.cli import main
from qdil.qd.checkpoint import config_differences
from tests.commands import SMOKE, qdil, start_qdil


def iterations(run_dir: Path) -> list[str]:
    with open(run_dir / "metrics.csv", newline="") as file:
        return [row["iteration"] for row in csv.DictReader(file)]


def dead_pid() -> int:
    """The id of a process that has exited (as a killed writer has)."""
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def test_a_run_killed_before_its_first_checkpoint_starts_over(
    tmp_path: Path, monkeypatch, capsys
) -> None:
    """SIGKILL after iteration 1, before the first checkpoint; --resume starts it over."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("QDIL_PLUGIN_PATH", raising=False)  # only ./plugins, absent here
    args = ["--qd.iterations", "2", "--logging.checkpoint_every", "2", "--name", "early"]
    run_dir = Path("runs") / "early"
    process = start_qdil("fit", str(SMOKE), *args, cwd=tmp_path)
    metrics = run_dir / "metrics.csv"
    deadline = time.time() + 600  # a loaded machine may take minutes for the first iteration
    # header and one row: iteration 1 is logged, the checkpoint comes after iteration 2
    while process.poll() is None and time.time() < deadline:
        if metrics.exists() and metrics.read_text().count("\n") >= 2:
            break
        time.sleep(0.05)
    process.send_signal(signal.SIGKILL)
    process.wait()
    assert process.returncode == -signal.SIGKILL, "the run must be killed, not finish"
    assert metrics.exists(), "the run logged no iteration before the deadline"
    checkpoint = run_dir / "checkpoints" / "last.pt"
    assert not checkpoint.exists() and iterations(run_dir) == ["1"]
    stale = run_dir / "checkpoints" / f".last.pt.tmp-{dead_pid()}"  # a killed write's litter
    stale.parent.mkdir(exist_ok=True)
    stale.write_bytes(b"half a checkpoint")

    with pytest.raises(SystemExit, match=f"`qdil fit --resume {run_dir}`"):
        main(["fit", str(SMOKE), *args])

    main(["fit", "--resume", str(run_dir)])
    stderr = capsys.readouterr().err
    assert "has no checkpoint" in stderr and "starting it over" in stderr
    assert f"removed {stale}" in stderr and not stale.exists()
    assert iterations(run_dir) == ["1", "2"]  # the killed attempt's row is not kept twice
    assert torch.load(checkpoint, weights_only=False)["iteration"] == 2


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A one-iteration smoke run with its checkpoint."""
    root = tmp_path_factory.mktemp("resume")
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(root)
        patch.delenv("QDIL_PLUGIN_PATH", raising=False)  # only ./plugins, absent here
        main(["fit", str(SMOKE), "--qd.iterations", "1", "--name", "done"])
    return root / "runs" / "done"


def _cells(config: dict) -> None:
    config["qd"]["cells"] = 20


def _actor_hidden(config: dict) -> None:
    config["policy"]["hidden"] = [64, 64]


EDITS = {
    "qd.cells": (_cells, False, ["qd.cells: 10 -> 20"]),
    "policy.hidden": (_actor_hidden, False, ["policy.hidden: [128, 128] -> [64, 64]"]),
    # a checkpoint of a qdil that did not store the recipe: the policy size still tells
    "policy.hidden, older checkpoint": (_actor_hidden, True, ["policies of", "policy.hidden"]),
}


@pytest.mark.parametrize(("edit", "older", "words"), list(EDITS.values()), ids=list(EDITS))
def test_resume_after_config_yaml_was_edited_is_refused(
    edit, older: bool, words: list[str], finished: Path, tmp_path: Path, monkeypatch
) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("QDIL_PLUGIN_PATH", raising=False)  # only ./plugins, absent here
    run_dir = tmp_path / "edited"
    shutil.copytree(finished, run_dir)
    config_path = run_dir / "config.yaml"
    config = yaml.safe_load(config_path.read_text())
    edit(config)
    config_path.write_text(yaml.safe_dump(config))
    checkpoint = run_dir / "checkpoints" / "last.pt"
    if older:
        state = torch.load(checkpoint, weights_only=False)
        del state["config"]
        torch.save(state, checkpoint)
    before = checkpoint.read_bytes()
    with pytest.raises(SystemExit) as refused:  # continued past its end: a finished run's
        # resume is a no-op that would not reach the checks
        main(["fit", "--resume", str(run_dir), "--qd.iterations", "2"])
    message = str(refused.value.code)
    for word in words:
        assert word in message, message
    assert "config.yaml" in message and "Traceback" not in message
    assert checkpoint.read_bytes() == before, "a refused resume must not touch the checkpoint"


def test_a_checkpoint_from_before_the_deployable_archive_resumes_and_is_scored(
    finished: Path, tmp_path: Path, monkeypatch, capsys
) -> None:
    """Older checkpoints kept an objectives-only ``learned_archive``: it is dropped."""
    from qdil.evaluation.rescore import rescore_archive
    from qdil.qd.checkpoint import CheckpointError, load_archive

    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("QDIL_PLUGIN_PATH", raising=False)  # only ./plugins, absent here
    run_dir = tmp_path / "older"
    shutil.copytree(finished, run_dir)
    checkpoint = run_dir / "checkpoints" / "last.pt"
    state = torch.load(checkpoint, weights_only=False)
    state["learned_archive"] = state.pop("deployable_archive")
    torch.save(state, checkpoint)
    with pytest.raises(CheckpointError, match="predates the deployable archive"):
        load_archive(run_dir, "deployable")
    _, summary = rescore_archive(run_dir, episodes=1, num_threads=1)
    assert summary["deployable"] is None and summary["metrics"]["num_elites"] > 0
    main(["fit", "--resume", str(run_dir), "--qd.iterations", "2"])
    assert "predates the deployable archive" in capsys.readouterr().err
    assert iterations(run_dir) == ["1", "2"]
    archive, iteration = load_archive(run_dir, "deployable")
    assert iteration == 2 and len(archive) > 0  # filled from iteration 2 on


def files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_a_finished_run_resumed_says_so_and_writes_nothing(
    finished: Path, tmp_path: Path, monkeypatch, capsys
) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("QDIL_PLUGIN_PATH", raising=False)  # only ./plugins, absent here
    shutil.copytree(finished, tmp_path / "done")
    before = files(tmp_path)
    main(["fit", "--resume", "done", "--logging.wandb", "offline"])
    assert capsys.readouterr().err.strip().splitlines() == [
        "done is finished: iteration 1 of 1; nothing to do (--qd.iterations N continues it to N)"
    ]
    assert files(tmp_path) == before  # no W&B folder, no provenance entry, nothing


def test_a_resume_online_without_a_login_stops_before_writing(
    finished: Path, tmp_path: Path
) -> None:
    run_dir = tmp_path / "online"
    shutil.copytree(finished, run_dir)
    before = files(run_dir)
    env = {k: v for k, v in os.environ.items() if not k.startswith("WANDB_")}
    env |= {"HOME": str(tmp_path), "NETRC": str(tmp_path / "no-netrc")}  # never logged in
    env.pop("QDIL_PLUGIN_PATH", None)
    args = ["--resume", str(run_dir), "--qd.iterations", "2", "--logging.wandb", "online"]
    done = qdil("fit", *args, cwd=tmp_path, env=env)
    assert done.returncode != 0
    assert (
        done.stderr.strip()
        .splitlines()[-1]
        .startswith("qdil fit: error: --logging.wandb online needs a W&B login")
    ), done.stderr
    assert "Traceback" not in done.stderr
    assert files(run_dir) == before


def test_a_resume_may_change_iterations_threads_and_logging_only() -> None:
    stored = {"qd": {"iterations": 3, "cells": 10}, "env": {"num_threads": None, "task": "W"}}
    stored["logging"] = {"progress": False, "checkpoint_every": 2}
    current = {
        "qd": {"iterations": 9, "cells": 10},
        "env": {"num_threads": 2, "task": "W"},
        "logging": {"progress": True, "checkpoint_every": 5},
    }
    assert config_differences(stored, current) == []
    current["env"]["task"] = "H"
    current["seed"] = 1
    assert config_differences(stored, current) == ["env.task: 'W' -> 'H'", "seed: (absent) -> 1"]


def test_keys_added_later_resume_when_a_checkpoint_lacks_them_at_their_implicit_value() -> None:
    stored = {"env": {"task": "W"}}
    assert config_differences(stored, {"env": {"task": "W", "backend": "mujoco"}}) == []
    assert config_differences(stored, {"env": {"task": "W", "backend": "warp"}}) == [
        "env.backend: 'mujoco' -> 'warp'"
    ]
    current = {"env": {"task": "W", "backend": "warp", "deterministic": False}}
    assert config_differences({"env": {"task": "W", "backend": "warp"}}, current) == []
    current["env"]["deterministic"] = True
    assert config_differences({"env": {"task": "W", "backend": "warp"}}, current) == [
        "env.deterministic: False -> True"
    ]
    bonus = {"bonus": {"enabled": True, "weight": 0.25}}
    current = {"bonus": {"enabled": True, "weight": 0.25, "type": "single_step", "offset": 0.0}}
    assert config_differences(bonus, current) == []
    current["bonus"]["type"] = "ebc"
    assert config_differences(bonus, current) == ["bonus.type: 'single_step' -> 'ebc'"]


def test_every_recorded_run_would_resume_with_the_code_of_today() -> None:
    """Runs made before a key was added resume (IMPLICIT_KEYS): each record's config.yaml,
    parsed as ``qdil fit --resume`` parses it, against itself as its checkpoint stored it."""
    from qdil.cli.fit import fit_parser, parse_fit
    from qdil.upgrades import upgraded

    root = Path(__file__).resolve().parents[2] / "docs" / "reports"
    distinct: dict[str, Path] = {}  # one record per recipe: seeds, names and logging aside
    for path in sorted(root.glob("*/runs/*/config.yaml")):
        recipe = yaml.safe_load(path.read_text())
        recipe = {key: value for key, value in recipe.items() if key not in ("seed", "name")}
        distinct.setdefault(yaml.safe_dump(recipe | {"logging": None}), path.parent)
    assert len(distinct) > 20
    parser = fit_parser()
    for record in distinct.values():
        stored = yaml.safe_load((record / "config.yaml").read_text())
        config = parse_fit(["--resume", str(record)])[0]
        config.name = stored.get("name")
        current = yaml.safe_load(parser.dump(config, skip_unset=False))
        assert config_differences(upgraded(stored), current) == [], record


def test_checkpoint_minutes_saves_between_distant_iteration_checkpoints(
    tmp_path: Path, monkeypatch
) -> None:
    """With checkpoint_every far away, the wall-clock rule saves after every long iteration."""
    import qdil.qd.loop as loop

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("WANDB_MODE", "disabled")
    saved: list[int] = []
    real_save = loop.save_checkpoint

    def recording_save(run):
        saved.append(run.state.iteration)
        return real_save(run)

    monkeypatch.setattr(loop, "save_checkpoint", recording_save)
    args = ["--qd.iterations", "2", "--logging.checkpoint_every", "100"]
    main(["fit", str(SMOKE), *args, "--logging.checkpoint_minutes", "1e-9", "--name", "often"])
    assert saved == [1, 2]
    saved.clear()
    main(["fit", str(SMOKE), *args, "--logging.checkpoint_minutes", "0", "--name", "at_end"])
    assert saved == [2], "checkpoint_minutes 0 must save by iteration count only"


def test_a_negative_checkpoint_minutes_is_refused_by_name(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as refused:
        main(["fit", str(SMOKE), "--logging.checkpoint_minutes", "-1"])
    message = str(refused.value.code)
    assert "logging.checkpoint_minutes must be at least 0, got -1.0" in message, message
    assert not Path("runs").exists(), "a refused recipe must not leave a run directory"
