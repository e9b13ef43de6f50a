"""``qdil export`` as a user runs its files: in a fresh Python process that imports numpy,
gymnasium and onnxruntime (or torch) only, in gymnasium's own task, on the episodes the JSON
records."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from qdil.cli import main
from qdil.evaluation.rescore import ReplaySettings
from qdil.qd.checkpoint import load_archive
from qdil.rl.collect import ActionMap
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import stats_from_fields
from qdil.rl.sampler import act
from tests.commands import SMOKE

ROOT = Path(__file__).resolve().parents[2]

# What a user's loop looks like: the only imports are numpy, gymnasium and the runtime.
PLAYER = """
import json, sys
import gymnasium as gym
import numpy as np
{runtime_import}

meta = json.load(open(sys.argv[1]))
{load}
env = gym.make(meta["task"], max_episode_steps=meta["max_episode_steps"], **meta["task_kwargs"])
episode = meta["episodes"][0]
obs, _ = env.reset(seed=episode["seed"])
seen, actions, total = [], [], 0.0
for _ in range(episode["length"]):
    batch = obs[None].astype(np.float32)
    action = {act}
    seen.append(batch[0].tolist()); actions.append(action.tolist())
    obs, reward, terminated, truncated, _ = env.step(action)
    total += float(reward)
qdil_like = sorted(m for m in sys.modules if m.split(".")[0] in ("qdil", "ribs", "mujoco_warp"))
print(json.dumps({{"obs": seen, "actions": actions, "return": total, "foreign": qdil_like}}))
"""

RUNTIMES = {
    "onnx": {
        "runtime_import": "import onnxruntime",
        "load": "policy = onnxruntime.InferenceSession(sys.argv[2])",
        "act": 'policy.run(["action"], {"obs": batch})[0][0]',
    },
    "torch": {
        "runtime_import": "import torch",
        "load": "policy = torch.export.load(sys.argv[2]).module()",
        "act": "policy(torch.from_numpy(batch)).detach().numpy()[0]",
    },
}  # fmt: skip


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A one-iteration smoke run of each task (50-step episodes)."""
    root = tmp_path_factory.mktemp("export")
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(root)
        patch.delenv("QDIL_PLUGIN_PATH", raising=False)
        for task in ("Walker2d-v5", "HalfCheetah-v5", "Humanoid-v5"):
            args = ["--env.task", task, "--qd.iterations", "1", "--name", task]
            main(["fit", str(SMOKE), *args])
    return root / "runs"


def qdil_actions(run_dir: Path, meta: dict, obs: np.ndarray) -> np.ndarray:
    """(T, A) the executed actions qdil's own sampler gives the elite for ``obs`` (T, obs_dim)."""
    archive, _ = load_archive(run_dir, meta["archive"])
    elites = archive.data()
    row = int(np.flatnonzero(elites["index"] == archive.grid_to_int_index([meta["cell"]])[0])[0])
    settings = ReplaySettings.of_run(run_dir)
    env = settings.make_env(1)
    actor = VectorizedActor(
        1, obs.shape[1], env.single_action_space.shape[0], settings.actor_hidden
    )
    actor.set_solutions(elites["solution"][[row]])
    fields = {key: elites[key][[row]] for key in ("obs_mean", "obs_var", "obs_count")}
    _, actions, _ = act(
        actor, stats_from_fields(fields), torch.from_numpy(obs), settings.obs_clip, None, True
    )
    action_map = ActionMap(env.single_action_space.low, env.single_action_space.high)
    return action_map(actions).numpy()


@pytest.mark.parametrize(
    ("task", "fmt"),
    [
        ("Walker2d-v5", "onnx"),
        ("Walker2d-v5", "torch"),
        ("HalfCheetah-v5", "onnx"),
        ("Humanoid-v5", "onnx"),
        ("Humanoid-v5", "torch"),
    ],
)
def test_an_exported_elite_plays_in_gymnasium_without_qdil(
    runs: Path, task: str, fmt: str, tmp_path: Path
) -> None:
    out = tmp_path / "gaits"
    main(["export", str(runs / task), "--best", "--format", fmt, "--out", str(out)])
    (meta_path,) = out.glob("*.json")
    meta = json.loads(meta_path.read_text())
    assert meta["task"] == task and meta["format"] == fmt and len(meta["episodes"]) == 5
    assert {"cell", "measures", "corrected_return", "run", "commit"} <= set(meta)
    assert [e["seed"] for e in meta["episodes"]] == [0, 1, 2, 3, 4]
    assert meta["corrected_return"] == pytest.approx(
        np.mean([e["return"] for e in meta["episodes"]])
    )
    policy_file = out / meta["file"]
    player = tmp_path / "player.py"
    player.write_text(PLAYER.format(**RUNTIMES[fmt]))
    done = subprocess.run(
        [sys.executable, str(player), str(meta_path), str(policy_file)],
        capture_output=True,
        text=True,
        check=True,
        cwd=tmp_path,
    )
    played = json.loads(done.stdout.splitlines()[-1])
    assert played["foreign"] == [], "the player must not import qdil, pyribs or Warp"
    episode = meta["episodes"][0]
    assert len(played["actions"]) == episode["length"]
    obs = np.asarray(played["obs"], dtype=np.float32)
    expected = qdil_actions(runs / task, meta, obs)
    gap = np.abs(np.asarray(played["actions"]) - expected).max()
    print(
        f"{task} {fmt}: largest action difference {gap:.2e}, return {played['return']:.6f} "
        f"against {episode['return']:.6f}"
    )
    assert gap <= 1e-5
    # the episode's own states follow the actions' last bits, which differ (see the guide)
    assert played["return"] == pytest.approx(episode["return"], rel=1e-2)


def test_export_refuses_a_cell_outside_the_grid_naming_it(runs: Path, tmp_path: Path) -> None:
    with pytest.raises(SystemExit, match=r"--cell 10 0 is not a cell of the 10×10 grid"):
        main(["export", str(runs / "Walker2d-v5"), "--cell", "10", "0", "--out", str(tmp_path)])
    assert not any(tmp_path.iterdir())
    taken = tmp_path / "policy.onnx"  # a file where the folder should be
    taken.write_text("kept")
    with pytest.raises(SystemExit, match=r"--out .*policy\.onnx is a file; give a folder"):
        main(["export", str(runs / "Walker2d-v5"), "--best", "--out", str(taken)])
    assert taken.read_text() == "kept"


def test_the_archive_as_a_minari_dataset_reads_back_as_demonstrations(
    runs: Path, tmp_path: Path, monkeypatch
) -> None:
    """Written offline, loaded with minari.load_dataset, imported by qdil: the same steps,
    and qdil's replayed contacts equal the ones the dataset keeps in ``infos``."""
    minari = pytest.importorskip("minari")
    from qdil.demos.importing import import_minari

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    run_dir = runs / "Walker2d-v5"
    main(["export", str(run_dir), "--format", "minari", "qdil/walker2d/gaits-v0", "--top", "3"])
    dataset = minari.load_dataset("qdil/walker2d/gaits-v0", download=False)
    assert dataset.total_episodes == 3 and dataset.env_spec.id == "Walker2d-v5"
    episodes = list(dataset.iterate_episodes())
    archive, _ = load_archive(run_dir, "true")
    elites = archive.data()
    for episode in episodes:
        steps = len(episode.actions)
        assert episode.observations.shape == (steps + 1, 17) and episode.actions.shape[1] == 6
        assert episode.terminations[-1] or episode.truncations[-1]
        assert not (episode.terminations[:-1].any() or episode.truncations[:-1].any())
        infos = episode.infos
        assert infos["foot_contact"].shape == (steps + 1, 2)
        (row,) = np.flatnonzero(elites["index"] == archive.grid_to_int_index(infos["cell"][:1])[0])
        np.testing.assert_array_equal(
            infos["measures"], np.repeat(elites["measures"][[row]], steps + 1, 0)
        )
    demos = import_minari("qdil/walker2d/gaits-v0")
    assert demos.task == "Walker2d-v5" and len(demos.episode_ends) == 3
    np.testing.assert_array_equal(
        demos.obs, np.concatenate([e.observations[:-1] for e in episodes])
    )
    np.testing.assert_array_equal(demos.actions, np.concatenate([e.actions for e in episodes]))
    contacts = np.concatenate([e.infos["foot_contact"][:-1] for e in episodes])
    np.testing.assert_array_equal(demos.contacts, contacts)
    with pytest.raises(SystemExit, match="exists already"):
        main(["export", str(run_dir), "--format", "minari", "qdil/walker2d/gaits-v0"])
