"""Demonstrations: selection, recording, the file format, validation and import."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from qdil.cli import main
from qdil.demos.generate import farthest_point_sampling, select_elites
from qdil.demos.importing import import_arrays, import_npz, qpos_from_obs, replay_contacts
from qdil.demos.io import DemoFormatError, demo_table, load_demos, read_header, save_demos

ROOT = Path(__file__).resolve().parents[2]


def test_farthest_point_sampling_starts_at_the_best_and_spreads() -> None:
    points = np.array([[0.5, 0.5], [0.51, 0.5], [0.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    picks = farthest_point_sampling(points, 4, start=0)
    assert picks[0] == 0
    assert set(picks[1:]) == {2, 3, 4}


def test_select_elites_ranks_by_objective_then_spreads_in_measure_space() -> None:
    elites = {
        "objective": np.array([10.0, 9.0, 8.0, 1.0, 7.0]),
        "measures": np.array([[0.5, 0.5], [0.52, 0.5], [0.1, 0.9], [1.0, 0.0], [0.9, 0.1]]),
    }
    rows = select_elites(elites, top=4, num=2)  # elite 3 is outside the top 4
    assert rows.tolist() == [0, 2]


def test_round_trip_keeps_aligned_steps_and_provenance(walker_demos, tmp_path) -> None:
    demos = load_demos(walker_demos, task="Walker2d-v5")
    assert demos.num_episodes == 2
    assert demos.obs.shape[1] == 17 and demos.actions.shape[1] == 6 and demos.contacts.shape[1] == 2
    # inside an episode s_{t+1} is the next row; δ(s_{t+1}) too
    inner = np.ones(len(demos.obs), bool)
    inner[demos.episode_ends - 1] = False
    np.testing.assert_array_equal(demos.next_obs[inner], demos.obs[1:][inner[:-1]])
    np.testing.assert_array_equal(demos.next_contacts[inner], demos.contacts[1:][inner[:-1]])
    assert np.all(demos.lengths <= 60)
    copy = tmp_path / "copy.npz"
    save_demos(demos, copy)
    again = load_demos(copy)
    np.testing.assert_array_equal(again.obs, demos.obs)
    np.testing.assert_allclose(again.returns, demos.returns, rtol=1e-5)
    header = read_header(copy)
    assert header["format"] == "qdil-demos" and header["version"] == 1
    assert [e["length"] for e in header["episodes"]] == demos.lengths.tolist()


def test_the_file_reads_with_numpy_alone(walker_demos) -> None:
    with np.load(walker_demos) as data:
        header = json.loads(str(data["header"]))
        assert data["obs"].shape == (header["num_steps"], header["obs_dim"])
        assert data["episode_ends"][-1] == header["num_steps"]


def test_contacts_replayed_from_states_equal_those_recorded(walker_demos) -> None:
    demos = load_demos(walker_demos)
    np.testing.assert_array_equal(replay_contacts("Walker2d-v5", demos.obs), demos.contacts)
    np.testing.assert_array_equal(
        replay_contacts("Walker2d-v5", demos.next_obs), demos.next_contacts
    )
    assert demos.contacts.any(), "the episodes must touch the floor somewhere"
    state = demos.metadata["state"]["qpos"]
    np.testing.assert_allclose(qpos_from_obs("Walker2d-v5", demos.obs)[:, 1:], state[:, 1:])


def test_import_from_plain_arrays_recomputes_contacts(walker_demos, tmp_path) -> None:
    demos = load_demos(walker_demos)
    starts = demos.episode_starts
    episodes = list(zip(starts, demos.episode_ends, strict=True))
    imported = import_arrays(
        "Walker2d-v5",
        [np.vstack([demos.obs[a:b], demos.next_obs[b - 1]]) for a, b in episodes],
        [demos.actions[a:b] for a, b in episodes],
        rewards=[demos.rewards[a:b] for a, b in episodes],
    )
    np.testing.assert_array_equal(imported.contacts, demos.contacts)
    np.testing.assert_array_equal(imported.next_contacts, demos.next_contacts)
    np.testing.assert_allclose(imported.returns, demos.returns)
    # the D4RL-style npz route gives the same
    d4rl = tmp_path / "d4rl.npz"
    terminals = np.zeros(len(demos.obs))
    timeouts = np.zeros(len(demos.obs))
    timeouts[demos.episode_ends - 1] = 1
    np.savez(
        d4rl,
        observations=demos.obs,
        actions=demos.actions,
        next_observations=demos.next_obs,
        rewards=demos.rewards,
        terminals=terminals,
        timeouts=timeouts,
    )
    np.testing.assert_array_equal(import_npz(str(d4rl), "Walker2d-v5").contacts, demos.contacts)


def test_import_from_a_minari_dataset_replays_contacts(walker_demos, tmp_path, monkeypatch) -> None:
    minari = pytest.importorskip("minari")
    import gymnasium as gym
    from minari.data_collector.episode_buffer import EpisodeBuffer

    from qdil.demos.importing import import_minari

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    demos = load_demos(walker_demos)
    buffers = []
    for i, (a, b) in enumerate(zip(demos.episode_starts, demos.episode_ends, strict=True)):
        steps = b - a
        buffers.append(
            EpisodeBuffer(
                id=i,
                observations=np.vstack([demos.obs[a:b], demos.next_obs[b - 1]]),
                actions=demos.actions[a:b],
                rewards=demos.rewards[a:b],
                terminations=np.r_[np.zeros(steps - 1, bool), demos.terminated[i]],
                truncations=np.r_[np.zeros(steps - 1, bool), not demos.terminated[i]],
            )
        )
    with pytest.warns(UserWarning, match="author"):  # minari asks for metadata we skip
        minari.create_dataset_from_buffers(
            "test/walker2d/qdil-v0",
            buffer=buffers,
            env=gym.make("Walker2d-v5"),
            algorithm_name="qdil",
            data_format="hdf5",
        )
    imported = import_minari("test/walker2d/qdil-v0")
    assert imported.task == "Walker2d-v5"
    np.testing.assert_array_equal(imported.contacts, demos.contacts)
    np.testing.assert_array_equal(imported.next_contacts, demos.next_contacts)
    np.testing.assert_array_equal(imported.terminated, demos.terminated)
    np.testing.assert_allclose(imported.returns, demos.returns, rtol=1e-5)


def test_import_refuses_misaligned_arrays() -> None:
    with pytest.raises(DemoFormatError, match=r"episode 0: actions must be \(3, 6\)"):
        import_arrays("Walker2d-v5", [np.zeros((4, 17))], [np.zeros((4, 6))])
    with pytest.raises(DemoFormatError, match=r"observations must be \(L\+1, 17\)"):
        import_arrays("Walker2d-v5", [np.zeros((4, 11))], [np.zeros((3, 6))])


def corrupt(source: Path, target: Path, **changes) -> Path:
    with np.load(source) as data:
        arrays = {key: data[key] for key in data.files}
    arrays.update(changes)
    arrays = {k: v for k, v in arrays.items() if v is not None}
    np.savez(target, **arrays)
    return target


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"header": None}, "no 'header' entry"),
        ({"obs": np.zeros((3, 17))}, "actions has .* rows, obs has 3: steps are not aligned"),
        ({"episode_ends": np.array([5, 5, 200])}, "must increase strictly"),
        ({"contacts": "bad"}, "2-D"),
    ],
)
def test_validation_says_what_is_wrong(walker_demos, tmp_path, changes, message) -> None:
    if isinstance(changes.get("contacts"), str):
        changes = {"contacts": np.zeros(5)}
    bad = corrupt(walker_demos, tmp_path / "bad.npz", **changes)
    with pytest.raises(DemoFormatError, match=message):
        load_demos(bad)


def test_validation_of_values_task_and_version(walker_demos, tmp_path) -> None:
    with np.load(walker_demos) as data:
        obs, header = data["obs"].copy(), json.loads(str(data["header"]))
    obs[3, 2] = np.nan
    with pytest.raises(DemoFormatError, match=r"obs holds a non-finite value at \[3, 2\]"):
        load_demos(corrupt(walker_demos, tmp_path / "nan.npz", obs=obs))
    with pytest.raises(
        DemoFormatError, match="recorded on 'Walker2d-v5', but the run's task is 'HalfCheetah-v5'"
    ):
        load_demos(walker_demos, task="HalfCheetah-v5")
    header["version"] = 99
    old = corrupt(walker_demos, tmp_path / "v99.npz", header=np.array(json.dumps(header)))
    with pytest.raises(DemoFormatError, match="format version 99; this qdil reads version 1"):
        load_demos(old)
    with pytest.raises(DemoFormatError, match="no such file"):
        load_demos(tmp_path / "missing.npz")


def test_demo_table_uses_population_std(walker_demos) -> None:
    demos = load_demos(walker_demos)
    table = demo_table(demos)
    lengths = demos.lengths.astype(float)
    assert f"| {lengths.std(ddof=0):.1f} |" in table.splitlines()[2]
    assert table.splitlines()[3].startswith("| Walker2d-v5 | 2 | Return |")


@pytest.fixture(scope="module")
def expert_run(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("expert")
    recipe = ROOT / "recipes" / "smoke" / "walker_true.yaml"
    import os

    cwd = os.getcwd()
    os.chdir(root)
    try:
        main(["fit", str(recipe), "--name", "expert"])
    finally:
        os.chdir(cwd)
    return root / "runs" / "expert"


def test_demos_from_a_run_follow_the_papers_pipeline(expert_run, tmp_path, capsys) -> None:
    out = tmp_path / "demos.npz"
    main(["demos", str(expert_run), "--top", "5", "--num", "3", "--out", str(out)])
    demos = load_demos(out, task="Walker2d-v5")
    assert demos.num_episodes == 3
    elites = demos.metadata["elites"]
    objectives = [e["archive_objective"] for e in elites]
    assert objectives[0] == max(objectives)  # farthest-point sampling starts at the best
    assert demos.metadata["selection"]["top"] == 5
    assert demos.metadata["deterministic"] is True
    assert demos.metadata["recipe"]["env"]["task"] == "Walker2d-v5"
    np.testing.assert_array_equal(replay_contacts("Walker2d-v5", demos.obs), demos.contacts)
    main(["demos", "--info", str(out)])
    printed = capsys.readouterr().out
    assert "| Walker2d-v5 | 3 | Length |" in printed and "episode 2: length" in printed


def test_a_minari_dataset_not_on_disk_says_how_to_download_it(tmp_path, monkeypatch) -> None:
    """minari's own error says ``download=True``, an argument no qdil command takes."""
    pytest.importorskip("minari")
    from qdil.cli import main

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "datasets"))
    dataset = "mujoco/walker2d/expert-v0"
    with pytest.raises(SystemExit) as stopped:
        main(["demos", "--import-minari", dataset, "--out", str(tmp_path / "w.npz")])
    message = str(stopped.value)
    assert message.startswith("qdil demos: error: Minari dataset 'mujoco/walker2d/expert-v0'")
    assert f"`minari download {dataset}`" in message
    assert str(tmp_path / "datasets") in message and "MINARI_DATASETS_PATH" in message
    assert "download=True" not in message
    assert not (tmp_path / "w.npz").exists()
