"""Contract tests run over every registered reward model: built-ins and plugins."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from _synthetic import ACT, OBS, K, as_rollout, demos_of, synthetic, train

from qdil.data import TransitionBatch
from qdil.rewards import get_reward, list_rewards
from qdil.rewards.bonus import ExplorationBonus

FAST = {"giril": {"pretrain_epochs": 30}}  # keep pretraining short in tests
NAMES = [entry.name for entry in list_rewards()]


def make(name: str):
    torch.manual_seed(0)
    return get_reward(name)(OBS, ACT, K, **FAST.get(name, {}))


@pytest.fixture(scope="module")
def expert() -> TransitionBatch:
    return synthetic(2.0, 400, seed=1)


@pytest.fixture(scope="module")
def policy() -> TransitionBatch:
    return synthetic(-2.0, 400, seed=2)


def trained(name: str, expert: TransitionBatch, policy: TransitionBatch, updates: int = 40):
    model, metrics = train(make(name), expert, policy, updates)
    assert all(np.isfinite(v) for m in metrics for v in m.values())
    return model


@pytest.mark.parametrize("name", NAMES)
def test_rewards_have_shape_dtype_and_are_finite(name, expert, policy) -> None:
    model = trained(name, expert, policy, updates=1)
    rewards = model.predict_reward(as_rollout(policy, envs=4), update=True)
    assert rewards.shape == (100, 4)
    assert rewards.dtype == torch.float32
    assert torch.isfinite(rewards).all()


@pytest.mark.parametrize("name", NAMES)
def test_training_reaches_every_parameter(name, expert, policy) -> None:
    fresh = make(name)
    before = {k: v.detach().clone() for k, v in fresh.named_parameters()}
    if not before:
        pytest.skip(f"{name} has no parameters")
    model = trained(name, expert, policy, updates=3)
    for key, value in model.named_parameters():
        assert not torch.equal(value.detach(), before[key]), f"{name}: {key} never changed"


@pytest.mark.parametrize("name", NAMES)
def test_tells_expert_from_non_expert_transitions(name, expert, policy) -> None:
    model = trained(name, expert, policy)
    if model.prefers_expert is None:
        pytest.skip(f"{name} does not compare transitions")
    held_out_e, held_out_p = synthetic(2.0, 200, seed=5), synthetic(-2.0, 200, seed=6)
    r_e = model.predict_reward(as_rollout(held_out_e)).mean()
    r_p = model.predict_reward(as_rollout(held_out_p)).mean()
    if model.prefers_expert:
        assert r_e > r_p, f"{name}: expert {r_e:.3f} <= policy {r_p:.3f}"
    else:
        assert r_e < r_p, f"{name}: curiosity reward should be lower on the expert"


@pytest.mark.parametrize("name", NAMES)
def test_state_survives_a_checkpoint_round_trip(name, expert, policy) -> None:
    model = trained(name, expert, policy, updates=2)
    rollout = as_rollout(policy, envs=2)
    model.predict_reward(rollout, update=True)  # stateful models build state
    state, extra = model.state_dict(), model.extra_state()
    expected = model.predict_reward(rollout, update=True)
    copy = make(name)
    if copy.needs_demos:
        copy.setup(demos_of(expert))
    copy.load_state_dict(state)
    copy.load_extra_state(extra)
    torch.testing.assert_close(copy.predict_reward(rollout, update=True), expected)


@pytest.mark.parametrize("name", NAMES)
def test_works_under_the_exploration_bonus(name, expert, policy) -> None:
    model = trained(name, expert, policy, updates=1)
    wrapped = ExplorationBonus(model, weight=2.0)
    rollout = as_rollout(policy, envs=4)
    base = model.predict_reward(rollout)
    total = wrapped.predict_reward(rollout)
    extra = total - base
    assert torch.all((extra >= 1.0) & (extra < 2.0))  # weight · [1/2, 1)
    assert wrapped.learned == model.learned and wrapped.needs_demos == model.needs_demos
