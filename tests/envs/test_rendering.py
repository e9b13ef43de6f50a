"""``render_mode="rgb_array"``: frames that move, and physics bit-for-bit as without them.

Skipped, naming why, where no OpenGL backend renders (CI without GL).
"""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest

import qdil  # noqa: F401 - registers qdil/<Task>-v5
from qdil.envs.vector import LocomotionVectorEnv

STEPS = 20


def rollout(env, actions: np.ndarray, render: bool) -> tuple[list, list]:
    """Everything the environment returns over ``actions``, and the frames drawn."""
    seen, frames = [env.reset(seed=3)], []
    for action in actions:
        seen.append(env.step(action))
        if render:
            frames.append(env.render())
    env.close()
    return seen, frames


def assert_same(first: list, second: list) -> None:
    """Bit-for-bit the same observations, rewards, flags and info arrays."""
    for a, b in zip(first, second, strict=True):
        for x, y in zip(a, b, strict=True):
            if isinstance(x, dict):
                assert x.keys() == y.keys()
                for key in x:
                    if isinstance(x[key], np.ndarray):
                        np.testing.assert_array_equal(x[key], y[key], err_msg=key)
            else:
                np.testing.assert_array_equal(x, y)


def test_the_vector_env_draws_its_first_simulation_and_physics_stays_the_same(gl: str) -> None:
    actions = np.random.default_rng(0).uniform(-1, 1, (STEPS, 2, 6)).astype(np.float32)
    plain, _ = rollout(LocomotionVectorEnv("Walker2d-v5", 2, num_threads=1), actions, False)
    env = LocomotionVectorEnv("Walker2d-v5", 2, num_threads=1, render_mode="rgb_array")
    assert env.metadata["render_modes"] == ["rgb_array"] and env.metadata["render_fps"] == 125
    drawn, frames = rollout(env, actions, True)
    assert_same(plain, drawn)
    assert all(len(f) == 1 and f[0].shape == (480, 480, 3) for f in frames)
    assert frames[0][0].dtype == np.uint8
    assert len({f[0].tobytes() for f in frames}) > STEPS // 2, "frames barely change"


def test_make_vec_passes_the_render_mode(gl: str) -> None:
    venv = gymnasium.make_vec("qdil/Walker2d-v5", num_envs=2, render_mode="rgb_array")
    venv.reset(seed=0)
    (frame,) = venv.render()
    assert frame.shape == (480, 480, 3) and frame.std() > 0
    venv.close()


def test_the_single_env_renders_and_physics_stays_the_same(gl: str) -> None:
    actions = np.random.default_rng(1).uniform(-1, 1, (STEPS, 6)).astype(np.float32)
    plain, _ = rollout(gymnasium.make("qdil/Walker2d-v5"), actions, False)
    drawn, frames = rollout(
        gymnasium.make("qdil/Walker2d-v5", render_mode="rgb_array"), actions, True
    )
    assert_same(plain, drawn)
    assert frames[0].shape == (480, 480, 3)
    assert len({f.tobytes() for f in frames}) > STEPS // 2, "frames barely change"


def test_an_unknown_render_mode_is_an_error() -> None:
    with pytest.raises(ValueError, match="render_mode 'human' is not one of"):
        LocomotionVectorEnv("Walker2d-v5", 1, render_mode="human")
