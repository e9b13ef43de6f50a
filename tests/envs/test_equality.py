"""qdil's batched tasks equal gymnasium's v5 tasks step for step (decision D9)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import qdil  # noqa: F401
from qdil.envs import TASKS

ALL_TASKS = list(TASKS)


def assert_close(actual: np.ndarray, expected: np.ndarray, what: str) -> None:
    """1e-6 relative, or absolute near zero."""
    scale = np.maximum(1.0, np.abs(expected))
    error = np.max(np.abs(actual - expected) / scale) if actual.size else 0.0
    assert error <= 1e-6, f"{what}: max relative error {error:.3g}"


def lockstep(task: str, mode: AutoresetMode, steps: int, num_envs: int = 3, **kwargs) -> int:
    """Steps qdil's and gymnasium's vector envs with the same actions; returns episode ends."""
    ours = gym.make_vec(f"qdil/{task}", num_envs=num_envs, autoreset_mode=mode, **kwargs)
    reference = gym.make_vec(
        task,
        num_envs=num_envs,
        vectorization_mode="sync",
        vector_kwargs={"autoreset_mode": mode},
        **kwargs,
    )
    obs, _ = ours.reset(seed=7)
    ref_obs, _ = reference.reset(seed=7)
    assert_close(obs, ref_obs, "reset observation")
    rng = np.random.default_rng(0)
    low, high = ours.single_action_space.low, ours.single_action_space.high
    ends = 0
    for t in range(steps):
        # 20 % beyond the bounds: MuJoCo clamps controls, the control cost does not
        actions = rng.uniform(1.2 * low, 1.2 * high, size=(num_envs, low.size)).astype(np.float32)
        obs, reward, terminated, truncated, info = ours.step(actions)
        ref_obs, ref_reward, ref_terminated, ref_truncated, ref_info = reference.step(actions)
        np.testing.assert_array_equal(terminated, ref_terminated, err_msg=f"terminated, step {t}")
        np.testing.assert_array_equal(truncated, ref_truncated, err_msg=f"truncated, step {t}")
        assert_close(obs, ref_obs, f"observation, step {t}")
        assert_close(reward, ref_reward, f"reward, step {t}")
        done = terminated | truncated
        if mode is AutoresetMode.SAME_STEP and done.any():
            for i in np.flatnonzero(done):
                assert_close(info["final_obs"][i], ref_info["final_obs"][i], f"final obs {t}")
        ends += int(done.sum())
    ours.close()
    reference.close()
    return ends


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize("task", ALL_TASKS)
def test_equal_to_gymnasium_over_1000_steps(task: str, mode: AutoresetMode) -> None:
    # 1010 steps: HalfCheetah never terminates, so its 1000-step truncation must be reached
    ends = lockstep(task, mode, steps=1010)
    assert ends >= 3, "the comparison must cross episode ends"


@pytest.mark.parametrize("task", ["Walker2d-v5", "HalfCheetah-v5"])
def test_equal_to_gymnasium_with_short_horizon_and_kwargs(task: str) -> None:
    kwargs = {"max_episode_steps": 25, "ctrl_cost_weight": 0.5, "reset_noise_scale": 0.05}
    ends = lockstep(task, AutoresetMode.NEXT_STEP, steps=120, **kwargs)
    assert ends >= 12


def test_disabled_autoreset_with_reset_mask_equals_gymnasium() -> None:
    mode = AutoresetMode.DISABLED
    ours = gym.make_vec("qdil/Hopper-v5", num_envs=4, autoreset_mode=mode)
    reference = gym.make_vec(
        "Hopper-v5", num_envs=4, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}
    )
    ours.reset(seed=1)
    reference.reset(seed=1)
    rng = np.random.default_rng(2)
    ends = 0
    for _ in range(300):
        actions = rng.uniform(-1, 1, size=(4, 3)).astype(np.float32)
        obs, reward, terminated, truncated, _ = ours.step(actions)
        ref_obs, ref_reward, *_ = reference.step(actions)
        assert_close(obs, ref_obs, "observation")
        assert_close(reward, ref_reward, "reward")
        done = terminated | truncated
        if done.any():
            ends += int(done.sum())
            obs, _ = ours.reset(options={"reset_mask": done})
            ref_obs, _ = reference.reset(options={"reset_mask": done})
            assert_close(obs, ref_obs, "observation after masked reset")
    assert ends >= 5


def test_reset_distribution_equals_gymnasium_for_many_seeds() -> None:
    ours = gym.make_vec("qdil/HalfCheetah-v5", num_envs=16)
    reference = gym.make_vec("HalfCheetah-v5", num_envs=16, vectorization_mode="sync")
    for seed in (0, 1, 99, 2**31):
        assert_close(ours.reset(seed=seed)[0], reference.reset(seed=seed)[0], f"seed {seed}")
    # seed=None keeps each generator's stream, as gymnasium does
    assert_close(ours.reset()[0], reference.reset()[0], "continued stream")


def test_physics_threads_and_chunks_do_not_change_results() -> None:
    """Threads, and the chunks of simulations prange hands them, leave every trajectory alone.

    Chunk size 0 is numba's static split (one block per thread), the default before chunks.
    """

    def trace(threads: int, chunk_size: int | None) -> np.ndarray:
        env = gym.make_vec("qdil/Walker2d-v5", num_envs=8, num_threads=threads)
        if chunk_size is not None:
            env.unwrapped.physics.chunk_size = chunk_size
        env.reset(seed=3)
        rng = np.random.default_rng(4)
        return np.stack([env.step(rng.uniform(-1, 1, (8, 6)))[0] for _ in range(60)])

    reference = trace(1, 0)
    for threads, chunk_size in [(2, 0), (1, None), (2, None), (2, 1), (2, 3), (2, 64)]:
        np.testing.assert_array_equal(trace(threads, chunk_size), reference)


def test_a_reset_inside_the_step_equals_a_reset_then_a_step() -> None:
    """``MujocoBatch.step(reset=...)`` (NEXT_STEP's one launch) is bit-identical to two calls."""
    rng = np.random.default_rng(5)

    def batch():
        env = gym.make_vec("qdil/Walker2d-v5", num_envs=6, num_threads=2)
        env.reset(seed=1)
        physics = env.unwrapped.physics
        for _ in range(5):
            physics.step(np.full((6, 6), 0.3), 4)
        return env, physics

    ctrl = rng.uniform(-1, 1, (6, 6))
    ids = np.array([1, 4])
    active = np.ones(6, dtype=bool)
    active[ids] = False
    env, fused = batch()
    qpos, qvel = env.unwrapped.draw_initial_states(ids)
    _, apart = batch()
    fused.step(ctrl, 4, active, reset=(ids, qpos, qvel))
    apart.reset(ids, qpos, qvel)
    apart.step(ctrl, 4, active)
    np.testing.assert_array_equal(fused.exported, apart.exported)
    np.testing.assert_array_equal(fused.sensordata, apart.sensordata)
    with pytest.raises(ValueError, match="also active"):
        fused.step(ctrl, 4, None, reset=(ids, qpos, qvel))


@pytest.mark.parametrize(
    ("task", "integrator"),
    [
        ("Walker2d-v5", None),  # RK4
        ("Humanoid-v5", None),  # RK4 with mj_rnePostConstraint
        ("HalfCheetah-v5", None),  # Euler
        # implicit and implicitfast share one call; with these models' dof damping alone,
        # implicitfast equals Euler bit for bit, so only implicit tells the branch apart
        ("Hopper-v5", "mjINT_IMPLICIT"),
    ],
)
def test_kernel_steps_equal_mj_step_bit_for_bit(task: str, integrator: str | None) -> None:
    """The kernel's split step (``mj_step1`` at the end, the rest at the next step's start)
    computes exactly ``mujoco.mj_step``: states, exports and contact flags, bit for bit.

    Covers every integrator the kernel dispatches on, resets inside the step and a
    simulation left out of some steps.
    """
    import copy

    import mujoco

    from qdil.envs.physics import MujocoBatch

    env = gym.make_vec(f"qdil/{task}", num_envs=3, autoreset_mode="Disabled").unwrapped
    env.reset(seed=2)
    model, task_ = copy.copy(env.model), env.task
    if integrator is not None:
        model.opt.integrator = getattr(mujoco.mjtIntegrator, integrator)
    exports = task_.exports(model)
    physics = MujocoBatch(model, 3, exports, rne_post_constraint=task_.needs_rne)
    start = np.array([0, 1, 2])
    physics.reset(start, *env.draw_initial_states(start))
    refs = []
    for data in physics.datas:
        ref = mujoco.MjData(model)
        ref.qpos[:], ref.qvel[:] = data.qpos, data.qvel
        mujoco.mj_forward(model, ref)
        refs.append(ref)
    rng = np.random.default_rng(6)
    for t in range(120):
        ctrl = rng.uniform(-1, 1, (3, model.nu))
        active = np.array([True, True, t % 3 != 0])
        reset = None
        if t % 40 == 39:  # simulation 1 starts over inside this step
            active[1] = False
            qpos, qvel = env.draw_initial_states(np.array([1]))
            reset = (np.array([1]), qpos, qvel)
            mujoco.mj_resetData(model, refs[1])
            refs[1].qpos[:], refs[1].qvel[:] = qpos[0], qvel[0]
            mujoco.mj_forward(model, refs[1])
        physics.step(np.ascontiguousarray(ctrl), task_.frame_skip, active, reset=reset)
        for i, ref in enumerate(refs):
            if active[i]:
                ref.ctrl[:] = ctrl[i]
                mujoco.mj_step(model, ref, task_.frame_skip)
                if task_.needs_rne:
                    mujoco.mj_rnePostConstraint(model, ref)
            data = physics.datas[i]
            np.testing.assert_array_equal(data.qpos, ref.qpos, err_msg=f"qpos {i}, step {t}")
            np.testing.assert_array_equal(data.qvel, ref.qvel, err_msg=f"qvel {i}, step {t}")
            for name, export in exports.items():
                field = getattr(ref, export.field).ravel()[export.start : export.stop]
                np.testing.assert_array_equal(physics.view(name)[i], field, err_msg=name)
            # contact flags at the state after the step, from MuJoCo's own contact list
            probe = mujoco.MjData(model)
            probe.qpos[:] = ref.qpos
            mujoco.mj_kinematics(model, probe)
            mujoco.mj_collision(model, probe)
            mujoco.mj_sensorPos(model, probe)
            np.testing.assert_array_equal(physics.sensordata[i], probe.sensordata)
