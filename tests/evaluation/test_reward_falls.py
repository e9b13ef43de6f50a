"""benchmarks/probes/reward_falls.py splits the reward before falls into the model and the bonus."""

from __future__ import annotations

import csv
import importlib.util
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from qdil.cli import main
from qdil.demos.io import load_demos
from qdil.rewards.bonus import ExplorationBonus

ROOT = Path(__file__).resolve().parents[2]
RECIPE = ROOT / "recipes" / "smoke" / "walker_il.yaml"
WEIGHT = 0.25


@pytest.fixture(scope="module")
def falls():
    spec = importlib.util.spec_from_file_location(
        "reward_falls", ROOT / "benchmarks" / "probes" / "reward_falls.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def run(walker_demos: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """WQDIL with the bonus and floor-priced absorbing states, two iterations."""
    root = tmp_path_factory.mktemp("falls")
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(root)
        patch.delenv("QDIL_PLUGIN_PATH", raising=False)
        main([
            "fit", str(RECIPE), "--reward", "mcwae_wgail", "--bonus.enabled", "true",
            "--bonus.weight", str(WEIGHT), "--reward.init_args.absorbing", "floor",
            "--reward.init_args.reward_form", "standardized_logit",
            "--demos.path", str(walker_demos), "--qd.iterations", "2", "--name", "falls",
        ])  # fmt: skip
    return root / "runs" / "falls"


def test_the_checkpoint_gives_the_reward_the_run_goes_on_with(
    falls, run, walker_demos, tmp_path, monkeypatch
):
    expert = load_demos(str(walker_demos)).transitions()
    sizes = expert.obs.shape[1], expert.actions.shape[1], expert.contacts.shape[1]
    reward, iteration = falls.load_reward(run, sizes)
    assert isinstance(reward, ExplorationBonus) and iteration == 2
    # a copy resumed for one more iteration logs the floor its training rollouts were priced
    # with: the one the checkpoint holds
    shutil.copytree(run, tmp_path / "runs" / "more")
    monkeypatch.chdir(tmp_path)
    main(["fit", "--resume", "runs/more", "--qd.iterations", "3"])
    with open(tmp_path / "runs" / "more" / "metrics.csv", newline="") as file:
        third = list(csv.DictReader(file))[2]
    assert float(reward.model.absorbing_floor) == pytest.approx(float(third["reward/absorbing"]))

    steps = falls.replay(run, reward, elites=8)
    near, far = steps["near"], steps["far"]
    assert len(near) == len(far) == len(steps["model"]) == len(steps["bonus"]) > 0
    assert not (near & far).any() and (near | far).all()
    # a smoke policy on Walker2d falls within the 50-step horizon of some episodes
    assert 0 < steps["falls"] <= steps["elites"]
    assert 0 < near.sum() <= 20 * steps["falls"]
    # the single-step bonus pays w / (1 + p) with p a share of visits
    assert np.all((steps["bonus"] >= WEIGHT / 2) & (steps["bonus"] <= WEIGHT))


def test_the_table_names_each_run(falls, run, walker_demos, capsys):
    falls.main([str(run), "--elites", "4", "--demos", str(walker_demos)])
    out = capsys.readouterr().out
    assert "| falls | 2 | 4 |" in out
    with pytest.raises(SystemExit):
        falls.main([str(run.parent / "absent")])
    assert "no checkpoint" in capsys.readouterr().err
