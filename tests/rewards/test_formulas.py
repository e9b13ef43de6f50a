"""Reward formulas against the paper's equations on hand-built cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from qdil.data import Rollout
from qdil.rewards.bonus import ExplorationBonus
from qdil.rewards.builtin import GAIL, PWIL
from qdil.rewards.nets import gail_reward, gradient_penalty


def rollout_of(
    contacts: torch.Tensor, obs: torch.Tensor | None = None, actions: torch.Tensor | None = None
) -> Rollout:
    steps, n, _ = contacts.shape
    obs = torch.zeros(steps, n, 1) if obs is None else obs
    actions = torch.zeros(steps, n, 1) if actions is None else actions
    zeros = torch.zeros(steps, n)
    starts = zeros.clone()
    starts[0] = 1
    return Rollout(
        obs,
        actions,
        contacts,
        obs,
        contacts,
        zeros,
        zeros,
        zeros,
        zeros,
        torch.ones(steps, n),
        starts,
    )


def test_gail_reward_is_minus_log_one_minus_sigmoid() -> None:
    logits = torch.tensor([-30.0, -2.0, 0.0, 1.5, 30.0])
    expected = [-math.log(1 - 1 / (1 + math.exp(-x)) + 1e-8) for x in logits.tolist()]
    np.testing.assert_allclose(gail_reward(logits).numpy(), expected, rtol=1e-5, atol=1e-7)
    assert gail_reward(torch.tensor(0.0)).item() == pytest.approx(math.log(2), rel=1e-6)


def test_gail_model_reward_matches_its_discriminator() -> None:
    model = GAIL(3, 2, 2)
    model.setup(None)
    batch = rollout_of(torch.zeros(4, 1, 2), torch.randn(4, 1, 3), torch.randn(4, 1, 2)).flat()
    logits = model.logits(model.features(batch))
    torch.testing.assert_close(model.reward(batch), -torch.log(1 - torch.sigmoid(logits) + 1e-8))


class _Base(GAIL):
    def __init__(self) -> None:
        super().__init__(1, 1, 2)

    def predict_reward(self, rollout: Rollout, *, update: bool = False) -> torch.Tensor:
        return torch.zeros(rollout.rewards.shape)


def test_bonus_equals_the_papers_equation_on_hand_built_counts() -> None:
    bonus = ExplorationBonus(_Base())
    bonus.counts[:] = torch.tensor([1.0, 1.0, 1.0, 5.0])  # cells 00, 10, 01, 11 (foot 1 = bit 0)
    contacts = torch.tensor([[[0.0, 0.0], [1.0, 1.0], [1.0, 0.0]]])  # one step, three envs
    rewards = bonus.predict_reward(rollout_of(contacts))
    expected = [1 / (1 + 1 / 8), 1 / (1 + 5 / 8), 1 / (1 + 1 / 8)]
    np.testing.assert_allclose(rewards[0].numpy(), expected, rtol=1e-6)
    np.testing.assert_array_equal(bonus.counts.numpy(), [1, 1, 1, 5])  # evaluation: no visits


def test_bonus_counts_visits_step_by_step_before_adding_them() -> None:
    bonus = ExplorationBonus(_Base())
    contacts = torch.tensor([[[1.0, 1.0], [1.0, 1.0]], [[1.0, 1.0], [0.0, 0.0]]])
    rewards = bonus.predict_reward(rollout_of(contacts), update=True)
    # step 0 sees the prior (1 each of 4); step 1 sees cell 11 with 3 of 6 visits
    np.testing.assert_allclose(rewards[0].numpy(), [1 / 1.25, 1 / 1.25], rtol=1e-6)
    np.testing.assert_allclose(rewards[1].numpy(), [1 / (1 + 3 / 6), 1 / (1 + 1 / 6)], rtol=1e-6)
    np.testing.assert_array_equal(bonus.counts.numpy(), [2, 1, 1, 4])


def test_bonus_shrinks_towards_one_half_for_a_dominant_pattern() -> None:
    bonus = ExplorationBonus(_Base())
    bonus.counts[:] = torch.tensor([1.0, 1.0, 1.0, 1e9])
    r = bonus.predict_reward(rollout_of(torch.tensor([[[1.0, 1.0], [0.0, 0.0]]])))
    assert r[0, 0].item() == pytest.approx(0.5, abs=1e-6)
    assert r[0, 1].item() == pytest.approx(1.0, abs=1e-6)


def test_bonus_out_of_the_fitness_goes_to_training_rollouts_only() -> None:
    contacts = torch.tensor([[[1.0, 1.0], [0.0, 0.0]]])
    paper, training_only = ExplorationBonus(_Base()), ExplorationBonus(_Base(), in_fitness=False)
    # evaluations: the archive objective sees the wrapped model's reward alone (zeros here)
    assert training_only.predict_reward(rollout_of(contacts)).abs().max().item() == 0.0
    assert paper.predict_reward(rollout_of(contacts)).min().item() == pytest.approx(0.8)
    # training: the same bonus and the same visit counts as the paper's placement
    torch.testing.assert_close(
        training_only.predict_reward(rollout_of(contacts), update=True),
        paper.predict_reward(rollout_of(contacts), update=True),
    )
    torch.testing.assert_close(training_only.counts, paper.counts)


def test_finer_bonus_grid_for_continuous_measures() -> None:
    bonus = ExplorationBonus(_Base(), cells=10)
    assert bonus.counts.shape == (100,)
    cells = bonus.cell(torch.tensor([[0.0, 0.0], [0.95, 0.0], [0.0, 1.0]]))
    assert cells.tolist() == [0, 9, 90]


def pwil_model(expert: np.ndarray, horizon: int) -> PWIL:
    model = PWIL(1, 1, 1, alpha=5.0, beta=5.0, horizon=horizon, use_actions=False)
    model.atoms = torch.tensor(expert, dtype=torch.float32)
    return model


def test_pwil_reward_is_alpha_where_the_agent_retraces_the_expert() -> None:
    model = pwil_model(np.array([[0.0], [3.0]]), horizon=2)
    obs = torch.tensor([[[0.0]], [[3.0]]])
    rewards = model.predict_reward(rollout_of(torch.zeros(2, 1, 1), obs=obs))
    np.testing.assert_allclose(rewards[:, 0].numpy(), [5.0, 5.0], rtol=1e-6)


def test_pwil_reward_matches_the_greedy_coupling_formula() -> None:
    # expert atoms at 0 and 10 (weight 1/2 each); T = 2 agent steps at 1 then 1:
    # step 1 moves its 1/2 to atom 0 (cost 1/2 · 1); step 2 must go to atom 10 (cost 1/2 · 9)
    model = pwil_model(np.array([[0.0], [10.0]]), horizon=2)
    obs = torch.tensor([[[1.0]], [[1.0]]])
    rewards = model.predict_reward(rollout_of(torch.zeros(2, 1, 1), obs=obs))
    scale = 5.0 * 2 / math.sqrt(1)
    expected = [5.0 * math.exp(-scale * 0.5), 5.0 * math.exp(-scale * 4.5)]
    np.testing.assert_allclose(rewards[:, 0].numpy(), expected, rtol=1e-5)


def test_pwil_pool_resets_at_episode_starts_and_persists_across_training_calls() -> None:
    model = pwil_model(np.array([[0.0], [10.0]]), horizon=2)
    first = rollout_of(torch.zeros(1, 1, 1), obs=torch.tensor([[[1.0]]]))
    second = rollout_of(torch.zeros(1, 1, 1), obs=torch.tensor([[[1.0]]]))
    second.starts[:] = 0  # continues the episode of the first call
    model.predict_reward(first, update=True)
    continued = model.predict_reward(second, update=True)
    assert continued.item() == pytest.approx(5.0 * math.exp(-10.0 * 4.5), rel=1e-5)
    fresh = model.predict_reward(second)  # evaluation: a fresh pool
    assert fresh.item() == pytest.approx(5.0 * math.exp(-10.0 * 0.5), rel=1e-5)


def test_gradient_penalty_is_zero_for_a_unit_norm_linear_critic() -> None:
    w = torch.tensor([0.6, 0.8])
    penalty = gradient_penalty(lambda x: x @ w, torch.randn(16, 2), torch.randn(16, 2))
    assert penalty.item() == pytest.approx(0.0, abs=1e-10)
    doubled = gradient_penalty(lambda x: x @ (2 * w), torch.randn(16, 2), torch.randn(16, 2))
    assert doubled.item() == pytest.approx(1.0, abs=1e-6)


def test_bonus_equals_the_step_by_step_loop_on_random_rollouts() -> None:
    g = torch.Generator().manual_seed(0)
    bonus = ExplorationBonus(_Base())
    counts = torch.ones(4, dtype=torch.float64)
    for _ in range(3):
        contacts = (torch.rand(50, 7, 2, generator=g) > 0.3).float()
        rollout = rollout_of(contacts)
        valid = (torch.rand(50, 7, generator=g) > 0.2).float()
        rollout = Rollout(**{**rollout.__dict__, "valid": valid})
        cells = bonus.cell(contacts)
        expected = torch.zeros(50, 7, dtype=torch.float64)
        for t in range(50):  # the paper's definition, one step at a time
            expected[t] = 1.0 / (1.0 + counts[cells[t]] / counts.sum())
            counts.index_add_(0, cells[t][valid[t] > 0], torch.ones(int(valid[t].sum())).double())
        rewards = bonus.predict_reward(rollout, update=True)
        torch.testing.assert_close(rewards, expected.float(), rtol=0, atol=0)
        torch.testing.assert_close(bonus.counts, counts, rtol=0, atol=0)


def test_gradient_penalty_draws_its_mixing_weights_where_the_inputs_live() -> None:
    # on a GPU, u drawn on the CPU met CUDA inputs (found by benchmarks/gpu_check.py on an
    # H100); the meta device shows the same mismatch without a GPU
    critic = torch.nn.Linear(3, 1).to("meta")
    inputs = torch.zeros(4, 3, device="meta")
    assert gradient_penalty(critic, inputs, inputs).device.type == "meta"
    # the CPU draws the same u as before, so CPU results keep their bits
    w = torch.tensor([0.6, 0.8, 0.0])
    real, fake = torch.randn(8, 3), torch.randn(8, 3)
    state = torch.get_rng_state()
    first = gradient_penalty(lambda x: (x @ w) ** 2, real, fake)
    torch.set_rng_state(state)
    u = torch.rand((8, 1))
    mixed = (u * real + (1 - u) * fake).requires_grad_(True)
    (grad,) = torch.autograd.grad(((mixed @ w) ** 2).sum(), mixed)
    assert first.item() == ((grad.norm(2, dim=1) - 1).square().mean()).item()
