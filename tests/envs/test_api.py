"""Registration, spaces and clear errors for bad input."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import qdil  # noqa: F401
from qdil.envs import TASKS
from qdil.envs.vector import LocomotionVectorEnv


@pytest.mark.parametrize("task", list(TASKS))
def test_registered_spaces_equal_gymnasium(task: str) -> None:
    venv = gym.make_vec(f"qdil/{task}", num_envs=5)
    assert isinstance(venv, LocomotionVectorEnv)
    assert venv.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    assert venv.max_episode_steps == 1000
    reference = gym.make(task)
    assert venv.single_observation_space == reference.observation_space
    assert venv.single_action_space == reference.action_space
    assert venv.observation_space.shape == (5, *reference.observation_space.shape)
    single = gym.make(f"qdil/{task}")
    assert single.observation_space == reference.observation_space
    assert single.spec.max_episode_steps == 1000
    _, info = single.reset(seed=0)
    assert info["foot_contact"].shape == (len(TASKS[task].feet),)


def test_unknown_task_names_the_known_ones() -> None:
    with pytest.raises(ValueError, match="known tasks: Walker2d-v5, HalfCheetah-v5"):
        LocomotionVectorEnv("Walker3d-v5", 2)


def test_unknown_keyword_names_the_accepted_ones() -> None:
    with pytest.raises(ValueError, match="ctrl_cost_weight"):
        gym.make_vec("qdil/Walker2d-v5", num_envs=2, ctrl_cost=0.1)


def test_bad_sizes_and_modes() -> None:
    with pytest.raises(ValueError, match="num_envs must be at least 1"):
        LocomotionVectorEnv("Walker2d-v5", 0)
    with pytest.raises(ValueError, match="autoreset_mode 'Sometimes'"):
        LocomotionVectorEnv("Walker2d-v5", 2, autoreset_mode="Sometimes")
    with pytest.raises(ValueError, match="num_threads"):
        LocomotionVectorEnv("Walker2d-v5", 2, num_threads=0)


@pytest.fixture(scope="module")
def walker() -> LocomotionVectorEnv:
    env = LocomotionVectorEnv("Walker2d-v5", 3)
    env.reset(seed=0)
    return env


def test_step_before_reset_is_refused() -> None:
    with pytest.raises(RuntimeError, match="call reset"):
        LocomotionVectorEnv("Walker2d-v5", 2).step(np.zeros((2, 6)))


@pytest.mark.parametrize(
    ("actions", "message"),
    [
        (np.zeros((3, 5)), r"shape \(num_envs, action_dim\) = \(3, 6\), got \(3, 5\)"),
        (np.zeros(6), r"got \(6,\)"),
        (np.zeros((3, 6), dtype=np.int64), "float32 or float64 array, got int64"),
        (np.array([[0.0] * 6, [np.nan] + [0.0] * 5, [0.0] * 6]), r"NaN or inf .* \[1\]"),
        (np.array([[np.inf] * 6] * 3), r"NaN or inf .* \[0, 1, 2\]"),
    ],
)
def test_bad_actions_are_refused(walker, actions, message) -> None:
    with pytest.raises(ValueError, match=message):
        walker.step(actions)


def test_bad_seed_list_and_reset_mask(walker) -> None:
    with pytest.raises(ValueError, match="2 seeds for 3 environments"):
        walker.reset(seed=[1, 2])
    with pytest.raises(ValueError, match="reset_mask must have shape"):
        walker.reset(options={"reset_mask": np.ones(2, bool)})


def test_out_of_range_actions_follow_gymnasium(walker) -> None:
    """MuJoCo clamps the control; the control cost sees the action as given."""
    walker.reset(seed=0)
    _, _, _, _, info = walker.step(np.full((3, 6), 3.0))
    np.testing.assert_allclose(info["reward_ctrl"], -1e-3 * 6 * 9.0)
    np.testing.assert_allclose(walker.physics.datas[0].ctrl, 3.0)


def test_disabled_mode_refuses_to_step_finished_envs() -> None:
    env = LocomotionVectorEnv("Walker2d-v5", 2, autoreset_mode="Disabled", max_episode_steps=2)
    env.reset(seed=0)
    env.step(np.zeros((2, 6)))
    env.step(np.zeros((2, 6)))
    with pytest.raises(RuntimeError, match="reset them with reset"):
        env.step(np.zeros((2, 6)))


def test_halfcheetah_loads_leave_no_mujoco_log(tmp_path, monkeypatch) -> None:
    # MuJoCo's default handler appends half_cheetah.xml's deprecation to ./MUJOCO_LOG.TXT.
    from qdil.demos.io import TaskShape

    monkeypatch.chdir(tmp_path)
    assert TaskShape.of("HalfCheetah-v5").obs_dim == 17
    with pytest.warns(UserWarning, match="MuJoCo: .*settotalmass"):
        gym.make("qdil/HalfCheetah-v5").close()
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
