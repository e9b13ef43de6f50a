"""Absorbing states: the batches a model learns them from, and what the loop adds for them."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from qdil.data import Rollout, TransitionBatch
from qdil.demos.dataset import DemoSet
from qdil.qd.absorbing import AbsorbingTail
from qdil.rewards.bonus import ExplorationBonus
from qdil.rewards.builtin.gail import GAIL
from qdil.rewards.builtin.pwil import PWIL

# three simulations over 6 steps: 0 falls at step 4 (its step 5 is evaluation padding);
# 1 is truncated at step 2; 2 falls at steps 1 and 5
DONES = torch.tensor(
    [[0, 0, 0], [0, 0, 1], [0, 1, 0], [0, 0, 0], [1, 0, 0], [0, 0, 1]], dtype=torch.float32
)
TERMINATED = DONES * torch.tensor([1.0, 0.0, 1.0])


def _rollout(valid: torch.Tensor | None = None) -> Rollout:
    g = torch.Generator().manual_seed(0)
    shape = (6, 3)
    return Rollout(
        obs=torch.randn(*shape, 4, generator=g),
        actions=torch.randn(*shape, 2, generator=g),
        contacts=(torch.rand(*shape, 2, generator=g) > 0.5).float(),
        next_obs=torch.randn(*shape, 4, generator=g),
        next_contacts=(torch.rand(*shape, 2, generator=g) > 0.5).float(),
        rewards=torch.zeros(shape),
        dones=DONES,
        terminated=TERMINATED,
        log_probs=torch.zeros(shape),
        valid=torch.ones(shape) if valid is None else valid,
        starts=torch.zeros(shape),
    )


def _gail() -> GAIL:
    torch.manual_seed(0)
    return GAIL(4, 2, 2, absorbing="learned", reward_form="raw", use_measures=True)


def test_a_batch_gains_one_flagged_copy_per_terminated_transition() -> None:
    batch = _rollout().flat()
    assert torch.equal(batch.terminated, TERMINATED.reshape(-1))
    extended = batch.with_absorbing()
    ended = TERMINATED.reshape(-1) > 0
    assert len(extended) == len(batch) + 3
    added = extended[torch.arange(len(batch), len(extended))]
    assert torch.equal(added.obs, batch.obs[ended])
    assert torch.equal(added.actions, batch.actions[ended])
    assert torch.all(added.absorbing == 1) and torch.all(added.dones == 0)
    assert torch.all(added.terminated == 0)
    assert torch.all(extended.absorbing[: len(batch)] == 0)
    quiet = batch[~ended]
    assert quiet.with_absorbing() is quiet  # nothing terminated: nothing added


def test_demonstrations_mark_the_last_step_of_terminated_episodes() -> None:
    n = 7
    demos = DemoSet(
        task="Walker2d-v5",
        obs=np.zeros((n, 4)),
        actions=np.zeros((n, 2)),
        contacts=np.zeros((n, 2)),
        rewards=np.zeros(n),
        next_obs=np.zeros((n, 4)),
        next_contacts=np.zeros((n, 2)),
        episode_ends=np.array([3, 5, 7]),
        terminated=np.array([True, False, True]),
    )
    batch = demos.transitions()
    assert batch.terminated.tolist() == [0, 0, 1, 0, 0, 0, 1]
    assert batch.dones.tolist() == [0, 0, 1, 0, 1, 0, 1]


def test_the_flag_is_an_input_and_the_update_sees_absorbing_transitions() -> None:
    model = _gail()
    assert model.input_dim == 4 + 2 + 2 + 1
    rows = _rollout().flat()[TERMINATED.reshape(-1) > 0]
    with torch.no_grad():
        plain = model.reward(rows)
    assert not torch.allclose(model.absorbing_reward(rows), plain)  # the flag changes x
    # a policy batch whose transitions all terminated: every minibatch pair it yields holds
    # absorbing copies on the policy side, none on the expert's
    policy = TransitionBatch(**{**rows.__dict__, "terminated": torch.ones(3)})
    flat = _rollout().flat()
    expert = TransitionBatch(**{**flat.__dict__, "terminated": torch.zeros(len(flat))})
    pairs = list(model.minibatches(expert, policy))
    assert pairs and all(p.absorbing.sum() > 0 for _, p in pairs)
    assert all(e.absorbing.sum() == 0 for e, _ in pairs)


def test_the_tail_discounts_or_fills_the_episode_to_the_time_limit() -> None:
    model = _gail()
    valid = torch.ones(6, 3)
    valid[5, 0] = 0.0
    rollout = _rollout(valid)
    ended = (TERMINATED * valid) > 0
    values = model.absorbing_reward(rollout.flat()[ended.reshape(-1)])
    discounted = AbsorbingTail(model, horizon=10, gamma=0.9, iteration=1)(rollout)
    expected = torch.zeros(6, 3)
    expected[ended] = values * (0.9 / 0.1)
    torch.testing.assert_close(discounted, expected)
    # an evaluation: each column one episode, padded after its end
    played = torch.zeros(6, 3)
    played[:5, 0], played[:3, 1], played[:2, 2] = 1.0, 1.0, 1.0
    evaluation = _rollout(played)
    ended = (TERMINATED * played) > 0
    values = model.absorbing_reward(evaluation.flat()[ended.reshape(-1)])
    tail = AbsorbingTail(model, horizon=10, gamma=None, iteration=1)
    expected = torch.zeros(6, 3)
    # time-major: simulation 2 fell after 2 steps (8 more to the limit), 0 after 5 (5 more)
    expected[ended] = values * torch.tensor([8.0, 5.0])
    torch.testing.assert_close(tail(evaluation), expected)
    assert tail.count == 2 and tail.mean == pytest.approx(float(values.mean()))
    assert torch.equal(tail(_rollout(torch.zeros(6, 3))), torch.zeros(6, 3))


def test_the_bonus_passes_the_absorbing_state_through_and_other_models_refuse() -> None:
    model = _gail()
    rows = _rollout().flat()[:4]
    wrapped = ExplorationBonus(model, weight=2.0)
    assert wrapped.absorbing
    torch.testing.assert_close(wrapped.absorbing_reward(rows), model.absorbing_reward(rows))
    plain = GAIL(4, 2, 2)
    assert not plain.absorbing and plain.input_dim == 6
    with pytest.raises(NotImplementedError, match="absorbing"):
        plain.absorbing_reward(rows)
    with pytest.raises(NotImplementedError, match=r"reward\.init_args\.absorbing"):
        PWIL(4, 2, 2).absorbing_reward(rows)


def test_the_floor_is_the_lowest_policy_reward_after_the_update() -> None:
    torch.manual_seed(0)
    model = GAIL(4, 2, 2, absorbing="floor", reward_form="raw")
    assert model.input_dim == 6  # no flag: nothing about the absorbing state is learned
    rows = _rollout().flat()
    assert torch.equal(model.absorbing_reward(rows), torch.zeros(len(rows)))  # before any
    model.price_absorbing(rows)
    with torch.no_grad():
        lowest = model.reward(rows).min()
    assert torch.equal(model.absorbing_reward(rows[:2]), torch.full((2,), float(lowest)))
    copy = GAIL(4, 2, 2, absorbing="floor", reward_form="raw")
    copy.load_state_dict(model.state_dict())  # checkpointed with the model
    assert float(copy.absorbing_floor) == float(lowest)
    with pytest.raises(ValueError, match="absorbing must be learned, floor, fixed or null"):
        GAIL(4, 2, 2, absorbing="always")


def test_fixed_absorbing_credits_a_true_termination_the_forms_lowest_reward() -> None:
    model = GAIL(4, 2, 2, reward_form="logd", absorbing="fixed")
    rollout = _rollout()
    r_min = math.log(1e-8)
    torch.testing.assert_close(model.absorbing_reward(rollout.flat()[:3]), torch.full((3,), r_min))
    # GAE's tail: r_min·γ/(1 − γ) where episodes terminated, not where the time limit cut
    expected = TERMINATED * (r_min * 0.9 / 0.1)
    torch.testing.assert_close(AbsorbingTail(model, 10, 0.9, 1)(rollout), expected)
    # a form bounded below by zero: the fixed value is the zero of a return that stops
    zero = GAIL(4, 2, 2, reward_form="calibrated_sigmoid", absorbing="fixed")
    assert torch.equal(AbsorbingTail(zero, 10, 0.9, 1)(rollout), torch.zeros(6, 3))
    with pytest.raises(ValueError, match=r"reward_form 'raw' has none; choose a form bounded"):
        GAIL(4, 2, 2, reward_form="raw", absorbing="fixed")
