"""Narrowing a MuJoCo Warp batch to the simulations still stepped changes no bit.

MuJoCo Warp steps every world of a ``Data``; ``WarpBatch.narrow`` moves the worlds that
will still be stepped into a smaller one, so that ended evaluation episodes stop costing
physics. On Warp's CPU device: the same steps with and without narrowing, compared bit for
bit, the states written back by a reset, and the simulated world-steps counted.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

pytest.importorskip("mujoco_warp", reason="the warp extra is not installed")

from qdil.envs.torch_vector import TorchVectorEnv
from qdil.envs.vector import LocomotionVectorEnv
from qdil.rl.episodes import EvaluationGroup, evaluate_groups
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd

NUM = 12


def _face(num: int = NUM, horizon: int | None = None) -> TorchVectorEnv:
    env = LocomotionVectorEnv(
        "Walker2d-v5",
        num,
        max_episode_steps=horizon,
        autoreset_mode="Disabled",
        backend="warp",
        device="cpu",
    )
    return TorchVectorEnv(env)


def _play(face: TorchVectorEnv, narrow: bool) -> list[torch.Tensor]:
    """Random actions; from step 3 only rows 1, 4, 5 step, from step 6 only row 4."""
    generator = torch.Generator().manual_seed(0)
    face.reset(seed=3)
    outputs = []
    for t in range(9):
        rows = [1, 4, 5] if t < 6 else [4]
        mask = torch.zeros(NUM, dtype=torch.bool)
        if t >= 3:
            mask[rows] = True
        if narrow and t in (3, 6):
            face.narrow(mask)
        actions = torch.rand((NUM, 6), generator=generator) * 2 - 1
        step = face.step(actions, mask if t >= 3 else None)
        outputs += [step.obs, step.reward, step.contacts, step.done]
    face.reset(seed=None)  # writes the narrowed states back, then resets every world
    outputs.append(face.physics.torch_exported.clone())
    for _ in range(2):
        outputs += [face.step(torch.rand((NUM, 6), generator=generator) * 2 - 1).obs]
    return outputs


def test_narrowed_steps_equal_full_ones_bit_for_bit() -> None:
    plain, narrowed = _face(), _face()
    expected, got = _play(plain, narrow=False), _play(narrowed, narrow=True)
    for a, b in zip(expected, got, strict=True):
        torch.testing.assert_close(b, a, rtol=0, atol=0)
    # 9 steps of 12 worlds; narrowed: 3 of 12, 3 of 4 (3 rows padded), 3 of 1, then 2 of 12
    assert plain.physics.world_steps == 11 * NUM
    assert narrowed.physics.world_steps == 3 * NUM + 3 * 4 + 3 * 1 + 2 * NUM


def test_widening_writes_the_narrowed_states_back() -> None:
    face = _face()
    face.reset(seed=1)
    physics = face.physics
    mask = torch.zeros(NUM, dtype=torch.bool)
    mask[[2, 7]] = True
    face.narrow(mask)
    for _ in range(3):
        face.step(torch.full((NUM, 6), 0.5), mask)
    narrowed_qpos = physics._worlds.field(physics.warp, "qpos")[:2].clone()
    physics.widen()
    np.testing.assert_array_equal(physics._tensor("qpos")[[2, 7]].numpy(), narrowed_qpos.numpy())
    assert physics._rows is None
    face.narrow(torch.zeros(NUM, dtype=torch.bool))  # nothing runs: the batch stays whole
    assert physics._rows is None and physics._worlds.size == NUM


def _policies(count: int) -> tuple[VectorizedActor, RunningMeanStd]:
    actor = VectorizedActor(count, 17, 6)
    solutions = np.stack([VectorizedActor.initial_solution(17, 6, seed=s) for s in range(count)])
    actor.set_solutions(solutions * np.array([3.0, 30.0, 10.0])[:count, None])
    return actor, RunningMeanStd(count, (17,))


def test_evaluations_with_narrowing_change_no_bit(monkeypatch) -> None:
    """Episodes of different lengths: the ended ones leave the batch, the scores stay."""
    actor, stats = _policies(3)

    def reward_fn(rollout):
        return rollout.next_obs[..., 0] - rollout.actions.square().sum(-1)

    def evaluate() -> tuple[list, int]:
        face = _face(24, horizon=40)
        group = EvaluationGroup(actor, stats, 4, 9, torch.Generator().manual_seed(2))
        other = EvaluationGroup(actor, stats, 4, 30, torch.Generator().manual_seed(5))
        results = evaluate_groups(face, [group, other], reward_fn, sync_every=2)
        return results, face.physics.world_steps

    narrowed, narrowed_steps = evaluate()
    monkeypatch.setattr(TorchVectorEnv, "narrow", lambda self, mask: None)
    plain, plain_steps = evaluate()
    for a, b in zip(plain, narrowed, strict=True):
        for field in ("objective", "true_objective", "measures", "lengths", "true_std"):
            np.testing.assert_array_equal(getattr(b, field), getattr(a, field), err_msg=field)
        assert a.env_steps == b.env_steps
    lengths = np.concatenate([result.lengths for result in plain])
    assert lengths.min() < 20 < lengths.max()  # episodes that end apart
    assert narrowed_steps < 0.8 * plain_steps
