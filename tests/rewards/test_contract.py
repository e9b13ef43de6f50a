"""Contract tests run over every registered reward model: built-ins and plugins."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from qdil.data import Rollout, TransitionBatch
from qdil.demos.dataset import DemoSet
from qdil.rewards import get_reward, list_rewards
from qdil.rewards.bonus import ExplorationBonus

OBS, ACT, K = 5, 2, 2
FAST = {"giril": {"pretrain_epochs": 30}}  # keep pretraining short in tests
NAMES = [entry.name for entry in list_rewards()]


def make(name: str):
    torch.manual_seed(0)
    return get_reward(name)(OBS, ACT, K, **FAST.get(name, {}))


def synthetic(center: float, size: int, seed: int) -> TransitionBatch:
    """Separable transitions: expert around +center, policy around -center."""
    g = torch.Generator().manual_seed(seed)
    obs = center + 0.5 * torch.randn(size, OBS, generator=g)
    actions = (0.4 * np.sign(center) + 0.1 * torch.randn(size, ACT, generator=g)).clamp(-1, 1)
    contacts = torch.tensor([[1.0, 0.0] if center > 0 else [0.0, 1.0]]).repeat(size, 1)
    next_obs = center + 0.5 * torch.randn(size, OBS, generator=g)
    dones = torch.zeros(size)
    dones[-1] = 1.0
    return TransitionBatch(
        obs, actions, contacts, next_obs, contacts.clone(), dones, torch.full((size,), -1.0)
    )


def demos_of(batch: TransitionBatch) -> DemoSet:
    n = len(batch)
    return DemoSet(
        task="Walker2d-v5",
        obs=batch.obs.double().numpy(),
        actions=batch.actions.double().numpy(),
        contacts=batch.contacts.numpy(),
        rewards=np.zeros(n),
        next_obs=batch.next_obs.double().numpy(),
        next_contacts=batch.next_contacts.numpy(),
        episode_ends=np.array([n // 2, n]),
        terminated=np.array([True, False]),
    )


def as_rollout(batch: TransitionBatch, envs: int = 1) -> Rollout:
    """Transitions laid out time-major, (len / envs, envs)."""
    steps = len(batch) // envs

    def tm(x: torch.Tensor) -> torch.Tensor:
        return x[: steps * envs].reshape(envs, steps, *x.shape[1:]).transpose(0, 1).contiguous()

    starts = torch.zeros(steps, envs)
    starts[0] = 1.0
    return Rollout(
        obs=tm(batch.obs),
        actions=tm(batch.actions),
        contacts=tm(batch.contacts),
        next_obs=tm(batch.next_obs),
        next_contacts=tm(batch.next_contacts),
        rewards=torch.randn(steps, envs),
        dones=tm(batch.dones),
        terminated=tm(batch.dones),
        log_probs=tm(batch.log_probs),
        valid=torch.ones(steps, envs),
        starts=starts,
    )


@pytest.fixture(scope="module")
def expert() -> TransitionBatch:
    return synthetic(2.0, 400, seed=1)


@pytest.fixture(scope="module")
def policy() -> TransitionBatch:
    return synthetic(-2.0, 400, seed=2)


def trained(name: str, expert: TransitionBatch, policy: TransitionBatch, updates: int = 40):
    from lightning import Fabric

    model = make(name)
    if model.learned:
        optimizers = model.configure_optimizers()
        optimizers = optimizers if isinstance(optimizers, list) else [optimizers]
        Fabric(accelerator="cpu", devices=1).setup(model, *optimizers)
    demos = demos_of(expert) if model.needs_demos else None
    model.setup(demos)
    model.pretrain(demos)
    if model.learned:
        for i in range(updates):
            metrics = model.update(expert, policy, iteration=i)
            assert all(np.isfinite(v) for v in metrics.values())
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
