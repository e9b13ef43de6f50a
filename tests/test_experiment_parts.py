"""A run built from Python objects is the run of the same recipe file, bit for bit."""

from __future__ import annotations

import csv
import functools
from pathlib import Path

import numpy as np
import pytest
import yaml

from qdil import Experiment, RecipeError
from qdil.config import EnvConfig, LoggingConfig, QDConfig
from qdil.qd import VPPO, PPGAEmitter
from qdil.recipe_parts import recipe_of
from qdil.rewards.builtin import TrueReward
from qdil.tracking import Tracker
from tests.commands import SMOKE

# recipes/smoke/walker_true.yaml, as objects
PARTS = {
    "reward": TrueReward,
    "env": EnvConfig(task="Walker2d-v5", num_envs=6, max_episode_steps=50),
    "rl": functools.partial(
        VPPO,
        rollout_length=16,
        jacobian_iterations=2,
        walk_iterations=2,
        num_minibatches=2,
        update_epochs=2,
    ),
    "qd": QDConfig(
        iterations=3,
        cells=10,
        branch_episodes=1,
        mean_episodes=2,
        threshold_min=-100.0,
        emitter=functools.partial(PPGAEmitter, batch_size=4),
    ),
    "logging": LoggingConfig(checkpoint_every=2, wandb="disabled", progress=False),
}


def _rows(run_dir: Path) -> list[dict[str, str]]:
    with open(run_dir / "metrics.csv", newline="") as file:
        return [
            {k: v for k, v in row.items() if not k.startswith("perf/") or k == "perf/env_steps"}
            for row in csv.DictReader(file)
        ]


def test_a_run_from_objects_equals_the_run_of_its_recipe_file(tmp_path: Path) -> None:
    with Experiment.from_parts(**PARTS, seed=0, root=tmp_path) as built:
        assert built.run_dir == tmp_path / "walker2d_true_reward-seed0"
        built.fit()
        objects = built.archive.data()
    with Experiment.from_recipe(SMOKE, seed=0, root=tmp_path, name="file") as read:
        read.fit()
        recipe = read.archive.data()
    assert _rows(built.run_dir) == _rows(tmp_path / "file")
    order_a, order_b = np.argsort(objects["index"]), np.argsort(recipe["index"])
    for key in objects:
        assert np.array_equal(objects[key][order_a], recipe[key][order_b]), key
    # the record names what ran, so the run resumes like any other
    config = yaml.safe_load((built.run_dir / "config.yaml").read_text())
    assert config["rl"]["init_args"]["rollout_length"] == 16
    assert config["qd"]["emitter"]["init_args"]["batch_size"] == 4
    with Experiment.resume(built.run_dir, ["--qd.iterations", "4"]) as again:
        again.fit()
        assert again.iteration == 4


def test_what_a_recipe_cannot_record_is_named() -> None:
    with pytest.raises(RecipeError, match=r"rl: a VPPO instance .*functools\.partial"):
        recipe_of(rl=VPPO())
    with pytest.raises(RecipeError, match="keywords only"):
        recipe_of(reward=functools.partial(TrueReward, 3))
    with pytest.raises(RecipeError, match="unknown recipe section 'rewards'"):
        recipe_of(rewards=TrueReward)
    assert recipe_of(rl=None, reward="gail", env={"task": "Hopper-v5"}) == {
        "rl": None,
        "reward": "gail",
        "env": {"task": "Hopper-v5"},
    }


def test_bad_values_built_in_python_are_refused_as_in_a_file(tmp_path: Path) -> None:
    """The same checks as a recipe file's, and a run that never started leaves no folder."""
    with pytest.raises(ValueError, match=r"^qd\.iterations must be at least 1, got 0; set it"):
        QDConfig(iterations=0)  # a section checks its own ranges, however it is built
    parts = {**PARTS, "qd": {"iterations": 0}}
    with pytest.raises(RecipeError, match=r"recipe built in Python: qd\.iterations must be at"):
        Experiment.from_parts(**parts, root=tmp_path)
    parts = {**PARTS, "env": EnvConfig(task="Walker3d-v5", num_envs=6)}
    with pytest.raises(ValueError, match=r"unknown task .Walker3d-v5.; known tasks: Walker2d"):
        Experiment.from_parts(**parts, root=tmp_path)
    assert not any(tmp_path.iterdir())


def test_runs_change_no_global_random_state_and_interleave_as_if_alone(tmp_path: Path) -> None:
    """Each run keeps its own torch generator state: two stepped in turns equal one alone,
    and the caller's generator is where it was after every build and step."""
    import torch

    with Experiment.from_recipe(SMOKE, seed=0, root=tmp_path, name="alone") as alone:
        alone.fit()
    torch.manual_seed(1234)
    before = torch.get_rng_state()
    first = Experiment.from_recipe(SMOKE, seed=0, root=tmp_path, name="first")
    second = Experiment.from_recipe(SMOKE, seed=0, root=tmp_path, name="second")
    assert torch.equal(torch.get_rng_state(), before)
    for _ in range(3):
        first.step()
        second.step()
        assert torch.equal(torch.get_rng_state(), before)
    first.close()
    second.close()
    for run in ("first", "second"):
        assert _rows(tmp_path / run) == _rows(tmp_path / "alone"), run


class Remembering(Tracker):
    """A user's tracker: qdil's records, and every iteration's QD-Score kept in memory."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.seen: list[tuple[int, float]] = []

    def log(self, metrics, iteration, run) -> None:
        super().log(metrics, iteration, run)
        self.seen.append((iteration, metrics["qd/qd_score"]))


def test_the_tracker_is_an_argument(tmp_path: Path) -> None:
    with Experiment.from_recipe(SMOKE, root=tmp_path, name="mine", tracker=Remembering) as run:
        run.fit()
        seen = run.run.tracker.seen
    logged = [(int(r["iteration"]), float(r["qd/qd_score"])) for r in _rows(tmp_path / "mine")]
    assert seen == logged and [i for i, _ in seen] == [1, 2, 3]
    with Experiment.resume(tmp_path / "mine", ["--qd.iterations", "4"], Remembering) as again:
        again.fit()
        assert [i for i, _ in again.run.tracker.seen] == [4]
