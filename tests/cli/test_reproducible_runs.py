"""``qdil fit`` is reproducible: the same seed twice (once in a process of its own), a resumed
run against an uninterrupted one, and a run stepped from Python (``qdil.experiment``) give
identical ``metrics.csv`` files and archives (timings aside), at a size where MKL splits the
PPO update's products among threads (larger than the smoke recipe)."""

from __future__ import annotations

import csv
import json
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from qdil.cli import main
from qdil.experiment import Experiment
from tests.commands import qdil

ROOT = Path(__file__).resolve().parents[2]
RECIPE = ROOT / "recipes" / "smoke" / "walker_il.yaml"
LARGER = [
    "--reward", "mcwae_wgail",
    "--bonus.enabled", "true",
    "--env.num_envs", "24",
    "--env.max_episode_steps", "100",
    "--rl.init_args.rollout_length", "32",
    "--qd.emitter.init_args.batch_size", "6",
    "--logging.checkpoint_every", "1",
]  # fmt: skip


def metrics(run_dir: Path) -> list[dict[str, str]]:
    """Rows of ``metrics.csv`` without the timings."""
    with open(run_dir / "metrics.csv", newline="") as file:
        return [
            {k: v for k, v in row.items() if not k.startswith("perf/") or k == "perf/env_steps"}
            for row in csv.DictReader(file)
        ]


def archives(run_dir: Path) -> list[dict[str, np.ndarray]]:
    """The true and deployable archives of the last checkpoint, cells in index order."""
    state = torch.load(run_dir / "checkpoints" / "last.pt", weights_only=False)
    found = []
    for which in ("true", "deployable"):
        data = pickle.loads(state[f"{which}_archive"]).data()
        order = np.argsort(data["index"])
        found.append({key: value[order] for key, value in data.items()})
    return found


def same_archives(a: list[dict[str, np.ndarray]], b: list[dict[str, np.ndarray]]) -> bool:
    return all(
        x.keys() == y.keys() and all(np.array_equal(x[k], y[k]) for k in x)
        for x, y in zip(a, b, strict=True)
    )


def layout_before_seats(config: dict) -> None:
    """A resolved recipe as qdil wrote it before the QD seats (issue 48): VPPO under
    ``qdil.rl`` and the policy's widths and clip among its arguments."""
    policy = config.pop("policy")
    config["rl"]["class_path"] = "qdil.rl.VPPO"
    config["rl"]["init_args"] |= {"actor_hidden": policy["hidden"], "obs_clip": policy["obs_clip"]}


def make_older(run_dir: Path) -> None:
    """Rewrite a run's config.yaml and checkpoint in the layout of before the seats."""
    config = yaml.safe_load((run_dir / "config.yaml").read_text())
    layout_before_seats(config)
    (run_dir / "config.yaml").write_text(yaml.safe_dump(config))
    path = run_dir / "checkpoints" / "last.pt"
    state = torch.load(path, weights_only=False)
    state["vppo"] = {**state.pop("rl"), "generator": state.pop("noise")}
    layout_before_seats(state["config"])
    torch.save(state, path)


@pytest.fixture(scope="module")
def runs(walker_demos: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four runs of one seed: twice three iterations (the second in a ``qdil fit`` process),
    and two iterations resumed to three, once as they are and once rewritten in the layout of
    before the seats."""
    root = tmp_path_factory.mktemp("reproducible")
    common = ["fit", str(RECIPE), *LARGER, "--demos.path", str(walker_demos)]
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(root)
        patch.delenv("QDIL_PLUGIN_PATH", raising=False)  # only ./plugins, absent here
        main([*common, "--qd.iterations", "3", "--name", "first"])
        qdil(*common, "--qd.iterations", "3", "--name", "second", cwd=root, check=True)
        main([*common, "--qd.iterations", "2", "--name", "resumed"])
        shutil.copytree("runs/resumed", "runs/older")
        make_older(Path("runs/older"))
        main(["fit", "--resume", "runs/resumed", "--qd.iterations", "3"])
        main(["fit", "--resume", "runs/older", "--qd.iterations", "3"])
    return root / "runs"


def test_the_same_seed_twice_gives_the_same_run(runs: Path) -> None:
    first = metrics(runs / "first")
    assert [row["iteration"] for row in first] == ["1", "2", "3"]
    assert metrics(runs / "second") == first
    assert same_archives(archives(runs / "first"), archives(runs / "second"))


def test_a_run_stepped_from_python_and_resumed_midway_equals_qdil_fit(
    runs: Path, walker_demos: Path, tmp_path: Path
) -> None:
    overrides = [*LARGER, "--demos.path", str(walker_demos), "--qd.iterations", "3"]
    with Experiment.from_recipe(RECIPE, overrides, seed=0, root=tmp_path, name="python") as run:
        assert (run.iteration, run.finished) == (0, False)
        for expected in (1, 2):
            metrics_of_step = run.step()
            # between steps: the iteration's metrics, the pyribs archive, the reward, θ_μ
            assert run.iteration == expected and "qd/qd_score" in metrics_of_step
            assert len(run.archive) > 0 and run.policy_mean.shape == (run.archive.solution_dim,)
            assert run.reward_model.name == "mcwae_wgail+bonus"
        run.checkpoint()
    with Experiment.resume(tmp_path / "python") as again:  # a new object, from the folder
        assert again.iteration == 2 and again.notes == [f"resuming {again.run_dir} at iteration 2"]
        again.fit()
        assert again.finished
    assert metrics(tmp_path / "python") == metrics(runs / "second")
    assert same_archives(archives(tmp_path / "python"), archives(runs / "second"))


def test_a_resumed_run_equals_the_uninterrupted_one(runs: Path) -> None:
    assert metrics(runs / "resumed") == metrics(runs / "first")
    assert same_archives(archives(runs / "resumed"), archives(runs / "first"))
    starts = json.loads((runs / "resumed" / "provenance.json").read_text())
    assert [start["from_iteration"] for start in starts] == [0, 2]


def test_a_run_from_before_the_seats_resumes_as_if_never_stopped(runs: Path) -> None:
    """Its config.yaml names qdil.rl.VPPO and rl.init_args.actor_hidden, its checkpoint keeps
    the action noise among VPPO's state: read as today's, it continues bit for bit, and the
    resume writes its config.yaml as today's."""
    config = yaml.safe_load((runs / "older" / "config.yaml").read_text())
    assert config["rl"]["class_path"] == "qdil.qd.VPPO" and config["policy"]["hidden"]
    assert metrics(runs / "older") == metrics(runs / "first")
    assert same_archives(archives(runs / "older"), archives(runs / "first"))
