"""Rollouts through the torch face equal those through the numpy face (warp, CPU device).

Same backend, seeds, policies and noise: observations, foot contacts, actions,
log-likelihoods, episode ends and starts agree exactly; rewards within 1e-6 (the control
cost is a float32 sum that torch and numpy may add up in a different order). Short
episodes (``max_episode_steps``) and a shallow reset queue make the rollouts cross several
autoresets and queue top-ups.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

pytest.importorskip("mujoco_warp", reason="the warp extra is not installed")

from qdil.envs.faces import HostFace
from qdil.envs.torch_vector import TorchVectorEnv
from qdil.envs.vector import LocomotionVectorEnv
from qdil.rl.collect import Collector
from qdil.rl.episodes import EvaluationGroup, evaluate_groups, evaluate_policies
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd

NUM, STEPS, HORIZON = 6, 12, 5
EXACT = ("obs", "next_obs", "actions", "contacts", "next_contacts", "dones", "terminated")


def _env(mode: str, num: int = NUM) -> LocomotionVectorEnv:
    return LocomotionVectorEnv(
        "Walker2d-v5",
        num,
        max_episode_steps=HORIZON,
        autoreset_mode=mode,
        backend="warp",
        device="cpu",
    )


def _policies(count: int) -> tuple[VectorizedActor, RunningMeanStd]:
    actor = VectorizedActor(count, 17, 6)
    solutions = np.stack([VectorizedActor.initial_solution(17, 6, seed=s) for s in range(count)])
    actor.set_solutions(solutions * 30)  # big weights: jerky policies that fall over
    stats = RunningMeanStd(count, (17,))
    return actor, stats


def test_training_rollouts_equal_the_numpy_path() -> None:
    env = _env("SameStep")
    actor, stats = _policies(3)
    results = []
    for collector in (Collector(HostFace(env)), Collector(TorchVectorEnv(env, reset_depth=3))):
        collector.start(seed=7)
        generator = torch.Generator().manual_seed(0)
        rollouts = [
            collector.collect(actor, stats, STEPS, generator, update_stats=False)
            for _ in range(2)  # the second call goes on from where the first stopped
        ]
        results.append((rollouts, collector.pop_episode_stats()))
    (numpy_rollouts, numpy_episodes), (torch_rollouts, torch_episodes) = results
    for (a, a_policy), (b, b_policy) in zip(numpy_rollouts, torch_rollouts, strict=True):
        for key in (*EXACT, "starts", "log_probs"):
            torch.testing.assert_close(getattr(b, key), getattr(a, key), rtol=0, atol=0)
        torch.testing.assert_close(b.rewards, a.rewards, rtol=0, atol=1e-6)
        torch.testing.assert_close(b_policy.norm_next_obs, a_policy.norm_next_obs, rtol=0, atol=0)
    assert numpy_rollouts[0][0].dones.sum() >= NUM  # every simulation reset at least once
    np.testing.assert_allclose(torch_episodes[0], numpy_episodes[0], rtol=0, atol=1e-5)
    assert torch_episodes[1] == numpy_episodes[1]


def test_evaluations_equal_the_numpy_path() -> None:
    env = _env("Disabled", 8)
    actor, stats = _policies(2)

    def reward_fn(rollout):
        return rollout.next_obs[..., 0] - rollout.actions.square().sum(-1)

    numpy_eval = evaluate_policies(
        HostFace(env), actor, stats, 3, seed=4, reward_fn=reward_fn, generator=torch.Generator()
    )
    group = EvaluationGroup(actor, stats, 3, 4, torch.Generator())
    device_eval = evaluate_groups(TorchVectorEnv(env), [group], reward_fn, sync_every=4)[0]
    assert device_eval.env_steps == numpy_eval.env_steps
    np.testing.assert_array_equal(device_eval.lengths, numpy_eval.lengths)
    np.testing.assert_array_equal(device_eval.measures, numpy_eval.measures)
    np.testing.assert_allclose(device_eval.true_objective, numpy_eval.true_objective, atol=1e-5)
    np.testing.assert_allclose(device_eval.objective, numpy_eval.objective, atol=1e-5)


def test_the_torch_face_needs_a_device_backend() -> None:
    env = LocomotionVectorEnv("Walker2d-v5", 2, autoreset_mode="SameStep")
    with pytest.raises(ValueError, match=r"env\.backend: warp"):
        TorchVectorEnv(env)


@pytest.mark.parametrize("task", ["Walker2d-v5", "Humanoid-v5-newton"])
def test_autoresets_without_the_solver_change_no_bit(task: str, monkeypatch) -> None:
    """An autoreset runs ``forward`` only up to the actuator forces, and nothing changes.

    Against a run whose resets call MuJoCo Warp's whole ``forward``: the same rollouts
    and the same physics state after them, bit for bit, across many autoresets
    (Humanoid's observation reads cinert, cvel and actuator forces; Walker2d's contacts).
    """
    from qdil.envs.warp_physics import WarpBatch

    def collect() -> tuple[list, dict[str, np.ndarray]]:
        env = LocomotionVectorEnv(
            task, 4, max_episode_steps=3, autoreset_mode="SameStep", backend="warp", device="cpu"
        )
        obs_dim, action_dim = (
            env.single_observation_space.shape[0],
            env.single_action_space.shape[0],
        )
        actor = VectorizedActor(2, obs_dim, action_dim)
        actor.set_solutions(
            np.stack([actor.initial_solution(obs_dim, action_dim, seed=s) for s in range(2)]) * 30
        )
        collector = Collector(TorchVectorEnv(env, reset_depth=2))
        collector.start(seed=3)
        rollout, _ = collector.collect(
            actor, RunningMeanStd(2, (obs_dim,)), 8, torch.Generator().manual_seed(1), False
        )
        data = env.physics.wdata
        state = {f: getattr(data, f).numpy().copy() for f in ("qpos", "qvel", "qacc_warmstart")}
        return [getattr(rollout, k) for k in (*EXACT, "rewards", "starts")], state

    observed_rollout, observed_state = collect()
    with monkeypatch.context() as patch:
        patch.setattr(
            WarpBatch, "_observed_stages", lambda self: self.mjw.forward(self.wmodel, self.wdata)
        )
        forward_rollout, forward_state = collect()
    assert float(observed_rollout[EXACT.index("dones")].sum()) >= 8  # resets happened
    for a, b in zip(observed_rollout, forward_rollout, strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0)
    for field, value in forward_state.items():
        np.testing.assert_array_equal(observed_state[field], value, err_msg=field)


def test_groups_played_side_by_side_equal_their_own_evaluations() -> None:
    """θ_μ's and the branches' episodes in one batch: each group's result, bit for bit.

    Stochastic actions (each group's own generator), a learned-reward objective, and
    groups of different sizes, statistics and episode counts.
    """

    def reward_fn(rollout):
        return rollout.next_obs[..., 0] - rollout.actions.square().sum(-1)

    actor_a, stats_a = _policies(1)
    actor_b, stats_b = _policies(3)
    stats_b.update(torch.randn(3, 20, 17, generator=torch.Generator().manual_seed(2)).double())
    specs = [(actor_a, stats_a, 4, 11), (actor_b, stats_b, 2, 40)]

    def groups() -> list[EvaluationGroup]:
        return [
            EvaluationGroup(a, s, e, seed, torch.Generator().manual_seed(seed))
            for a, s, e, seed in specs
        ]

    env = TorchVectorEnv(_env("Disabled", 12))
    batched = evaluate_groups(env, groups(), reward_fn, sync_every=4)
    alone = [evaluate_groups(env, [g], reward_fn, sync_every=4)[0] for g in groups()]
    for a, b in zip(batched, alone, strict=True):
        assert a.env_steps == b.env_steps
        for field in ("objective", "true_objective", "measures", "lengths", "true_std"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)


@pytest.mark.parametrize("mode", ["SameStep", "Disabled"])
def test_what_the_face_hands_out_is_not_changed_by_later_steps(mode: str) -> None:
    """The face keeps its state in tensors it updates in place (so that a CUDA graph can
    replay its step); what ``reset``, ``step`` and ``episode_statistics`` return are
    copies, which callers may keep (the collector stacks a rollout's steps at its end)."""
    face = TorchVectorEnv(_env(mode), reset_depth=3)
    obs, _ = face.reset(seed=3)
    kept = {"reset obs": obs}
    actions = torch.full((NUM, 6), 0.7)
    step = face.step(actions)
    kept |= {f"step {name}": tensor for name, tensor in step._asdict().items()}
    kept |= dict(zip(["returns", "lengths"], face.episode_statistics()[:2], strict=True))
    saved = {name: tensor.clone() for name, tensor in kept.items()}
    for _ in range(HORIZON + 2):  # past an episode end: resets rewrite the state too
        face.step(-actions)
    if mode == "Disabled":
        face.reset(seed=4)
    for name, tensor in kept.items():
        torch.testing.assert_close(tensor, saved[name], rtol=0, atol=0, msg=name)


def test_a_training_step_changes_no_python_state() -> None:
    """What a CUDA graph replays (``StepGraph``) is the step's kernels only: the step body
    may write its tensors in place, but must not rebind an attribute of the face or the
    physics (a replay would not), whatever episodes end in it. World-steps are counted
    outside it."""
    face = TorchVectorEnv(_env("SameStep"), reset_depth=3)
    face.reset(seed=5)
    actions = torch.full((NUM, 6), 0.9)
    physics = face.physics

    def state() -> dict[str, object]:
        kept = {f"face.{k}": v for k, v in vars(face).items()}
        kept |= {f"physics.{k}": v for k, v in vars(physics).items() if k != "world_steps"}
        return {k: (id(v), v.data_ptr()) if torch.is_tensor(v) else id(v) for k, v in kept.items()}

    before = state()
    ended = 0
    for t in range(HORIZON + 2):  # past the episodes' ends: the autoreset runs too
        ended += int(face._advance(actions if t % 2 else -actions).done.sum())
    assert ended > 0
    assert state() == before
