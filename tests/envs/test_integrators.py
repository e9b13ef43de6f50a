"""``env.integrator``: another integrator than the task model's, on both backends.

qdil's task with another integrator equals gymnasium's task whose model steps with that
integrator, as the v5 tasks equal gymnasium's (tests/envs/test_equality.py), and it moves
the trajectories; MuJoCo Warp is given the same integrator.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from qdil.envs.integrators import INTEGRATORS, changed_integrator, own_integrator, task_label
from qdil.envs.tasks import make_task
from qdil.envs.vector import LocomotionVectorEnv

NUM = 3


def test_the_task_models_own_integrators() -> None:
    own = {
        task: own_integrator(make_task(task).xml_path)
        for task in ("Walker2d-v5", "HalfCheetah-v5", "Humanoid-v5")
    }
    assert own == {"Walker2d-v5": "rk4", "HalfCheetah-v5": "euler", "Humanoid-v5": "rk4"}
    for task, name in own.items():
        model = LocomotionVectorEnv(task, 1).model
        assert model.opt.integrator == INTEGRATORS[name]
        assert model.opt.integrator == gym.make(task).unwrapped.model.opt.integrator
    walker = make_task("Walker2d-v5").xml_path
    assert changed_integrator(walker, "rk4") is None and changed_integrator(walker, None) is None
    assert changed_integrator(walker, "euler") == "euler"
    assert task_label("Walker2d-v5", "euler") == "Walker2d-v5 (euler)"
    with pytest.raises(ValueError, match=r"env\.integrator"):
        LocomotionVectorEnv("Walker2d-v5", 1, integrator="verlet")


@pytest.mark.parametrize(
    ("task", "integrator"),
    [("Walker2d-v5", "euler"), ("Walker2d-v5", "implicitfast"), ("HalfCheetah-v5", "rk4")],
)
def test_equal_to_gymnasium_stepping_with_the_same_integrator(task: str, integrator: str) -> None:
    ours = LocomotionVectorEnv(task, NUM, integrator=integrator)
    default = LocomotionVectorEnv(task, NUM)
    reference = gym.make_vec(task, num_envs=NUM, vectorization_mode="sync")
    for env in reference.envs:
        env.unwrapped.model.opt.integrator = INTEGRATORS[integrator]
    assert ours.model.opt.integrator == INTEGRATORS[integrator] != default.model.opt.integrator
    assert ours.factory.keywords["integrator"] == integrator  # remote shards build it too
    obs, ref_obs, default_obs = (
        ours.reset(seed=7)[0],
        reference.reset(seed=7)[0],
        default.reset(seed=7)[0],
    )
    np.testing.assert_allclose(obs, ref_obs, rtol=1e-6, atol=1e-6)
    rng = np.random.default_rng(0)
    low, high = ours.single_action_space.low, ours.single_action_space.high
    ends, moved = 0, 0.0
    for t in range(150):
        actions = rng.uniform(low, high, size=(NUM, low.size)).astype(np.float32)
        obs, reward, terminated, truncated, _ = ours.step(actions)
        ref_obs, ref_reward, ref_terminated, ref_truncated, _ = reference.step(actions)
        default_obs = default.step(actions)[0]
        np.testing.assert_array_equal(terminated, ref_terminated, err_msg=f"step {t}")
        np.testing.assert_array_equal(truncated, ref_truncated, err_msg=f"step {t}")
        np.testing.assert_allclose(obs, ref_obs, rtol=1e-6, atol=1e-6, err_msg=f"step {t}")
        np.testing.assert_allclose(reward, ref_reward, rtol=1e-6, atol=1e-6, err_msg=f"step {t}")
        ends += int((terminated | truncated).sum())
        moved = max(moved, float(np.abs(obs - default_obs).max()))
    assert moved > 1e-3  # the integrator changed the trajectories
    if task == "Walker2d-v5":
        assert ends > 0  # the comparison crossed a fall and its reset


def test_warp_steps_with_the_integrator_asked_for_and_agrees_with_the_c_backend() -> None:
    mjw = pytest.importorskip("mujoco_warp")
    make = dict(num_envs=NUM, autoreset_mode="Disabled", integrator="euler")
    c_env = LocomotionVectorEnv("Walker2d-v5", **make)
    warp_env = LocomotionVectorEnv("Walker2d-v5", backend="warp", device="cpu", **make)
    assert warp_env.physics.wmodel.opt.integrator == mjw.IntegratorType.EULER
    c_env.reset(seed=3)
    warp_env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(10):  # each step from the C simulations' state, as test_warp_backend's
        warp_env.physics.reset(
            np.arange(NUM), c_env.physics.view("qpos"), c_env.physics.view("qvel")
        )
        actions = rng.uniform(-1, 1, (NUM, 6))
        c_env.step(actions)
        warp_env.step(actions)
        for field, atol in (("qpos", 1e-5), ("qvel", 2e-3)):
            np.testing.assert_allclose(
                warp_env.physics.view(field), c_env.physics.view(field), rtol=0, atol=atol
            )


def test_a_run_with_another_integrator_says_so_and_replays_with_it(tmp_path, capsys) -> None:
    from qdil.evaluation.rescore import ReplaySettings
    from qdil.evaluation.runs import load_run
    from tests.commands import SMOKE, cli

    args = ["fit", str(SMOKE), "--qd.iterations", "1", "--env.integrator", "euler"]
    code, _, err = cli([*args, "--logging.root", str(tmp_path)], capsys)
    assert code == 0, err
    run_dir = tmp_path / "walker_true_euler-seed0"  # the name says it is not Walker2d-v5
    assert load_run(run_dir).task_label == "Walker2d-v5 (euler)"  # the report's column
    settings = ReplaySettings.of_run(run_dir)  # qdil eval, render and export replay with it
    assert settings.integrator == "euler"
    assert settings.make_env(1).model.opt.integrator == INTEGRATORS["euler"]
