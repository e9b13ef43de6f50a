"""Foot-contact flags and episode statistics (decision D8)."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.wrappers import TimeLimit

import qdil  # noqa: F401
from qdil.envs import TASKS
from qdil.envs.contacts import ContactProbe, FootContacts, scan_contacts


def test_probe_matches_mj_forward_contact_list() -> None:
    """The reference scan equals MuJoCo's own contact list after mj_forward."""
    env = gym.make("Walker2d-v5").unwrapped
    probe = ContactProbe(env.model, TASKS["Walker2d-v5"].feet)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    touching = 0
    for _ in range(400):
        _, _, terminated, _, _ = env.step(rng.uniform(-1, 1, 6))
        data = mujoco.MjData(env.model)
        data.qpos[:] = env.data.qpos
        data.qvel[:] = env.data.qvel
        mujoco.mj_forward(env.model, data)
        expected = scan_contacts(data, probe.feet, probe.floor)
        np.testing.assert_array_equal(probe(env.data.qpos), expected)
        touching += int(expected.any())
        if terminated:
            env.reset()
    assert touching > 50, "the trajectory must include contacts"


@pytest.mark.parametrize("task", list(TASKS))
def test_vector_flags_equal_direct_scan_and_episode_stats(task: str) -> None:
    """Sensor-based flags of the batched env equal a direct scan of MuJoCo's contacts."""
    num_envs = 3
    venv = gym.make_vec(f"qdil/{task}", num_envs=num_envs, max_episode_steps=120)
    feet = TASKS[task].feet
    # FootContacts outside a 120-step TimeLimit sees the truncation itself
    singles = [
        FootContacts(TimeLimit(gym.make(task, max_episode_steps=-1), 120), feet, horizon=120)
        for _ in range(num_envs)
    ]
    _, info = venv.reset(seed=11)
    flags = [s.reset(seed=11 + i)[1]["foot_contact"] for i, s in enumerate(singles)]
    np.testing.assert_array_equal(np.stack(flags), info["foot_contact"])
    k = len(TASKS[task].feet)
    assert info["foot_contact"].shape == (num_envs, k)

    rng = np.random.default_rng(5)
    low, high = venv.single_action_space.low, venv.single_action_space.high
    pending = [False] * num_envs
    returns = np.zeros(num_envs)
    flag_sums = np.zeros((num_envs, k))
    lengths = np.zeros(num_envs, dtype=int)
    episodes = contact_steps = 0
    for _ in range(400):
        actions = rng.uniform(low, high, (num_envs, low.size)).astype(np.float32)
        _, reward, _, _, info = venv.step(actions)
        assert set(np.unique(info["foot_contact"])) <= {0.0, 1.0}
        for i, single in enumerate(singles):
            if pending[i]:  # NEXT_STEP: this step reset sub-environment i
                _, single_info = single.reset()
                pending[i] = False
                returns[i], flag_sums[i], lengths[i] = 0.0, 0.0, 0
            else:
                _, _, term, trunc, single_info = single.step(actions[i])
                returns[i] += reward[i]
                flag_sums[i] += info["foot_contact"][i]
                lengths[i] += 1
                pending[i] = term or trunc
                if pending[i]:
                    episodes += 1
                    assert info["_episode"][i]
                    episode = {key: value[i] for key, value in info["episode"].items()}
                    assert episode["l"] == lengths[i] == single_info["episode"]["l"]
                    np.testing.assert_allclose(episode["r"], returns[i], rtol=1e-9)
                    np.testing.assert_allclose(episode["measures"], flag_sums[i] / lengths[i])
                    np.testing.assert_allclose(single_info["episode"]["r"], returns[i], rtol=1e-6)
                    np.testing.assert_allclose(
                        single_info["episode"]["measures"], episode["measures"]
                    )
            np.testing.assert_array_equal(single_info["foot_contact"], info["foot_contact"][i])
            contact_steps += int(info["foot_contact"][i].any())
    assert episodes >= 3
    assert contact_steps > 50


def test_reward_terms_sum_to_reward() -> None:
    for task in TASKS:
        env = gym.make_vec(f"qdil/{task}", num_envs=4)
        env.reset(seed=0)
        low, high = env.single_action_space.low, env.single_action_space.high
        for _ in range(5):
            _, reward, _, _, info = env.step(
                np.random.default_rng(0).uniform(low, high, (4, low.size))
            )
            terms = sum(info[key] for key in info if key.startswith("reward_") and key[0] != "_")
            np.testing.assert_allclose(terms, reward, rtol=1e-9, atol=1e-12)
