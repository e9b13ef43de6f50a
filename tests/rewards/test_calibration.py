"""The calibrated Wasserstein-critic reward and the learned-reward / bonus balance."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from qdil.rewards.bonus import ExplorationBonus
from qdil.rewards.builtin.wae import MCWAEWGAIL
from qdil.rewards.contract import ACT, OBS, K, as_rollout, synthetic, train
from qdil.rewards.forms import ScoreStats, calibrated_logit, standardized_logit
from qdil.rewards.nets import gail_reward


def stats(expert_mean: float, policy_mean: float, policy_std: float = 1.0, min_gap: float = 1.0):
    return ScoreStats(expert_mean, policy_mean, policy_std, min_gap)


def test_calibrated_logit_puts_expert_and_policy_means_at_plus_and_minus_two() -> None:
    scores = torch.tensor([11.0, -1.0, 5.0, 23.0])
    logits = calibrated_logit(scores, stats(11.0, -1.0))
    np.testing.assert_allclose(logits.numpy(), [2.0, -2.0, 0.0, 6.0], rtol=1e-6)
    rewards = gail_reward(logits)
    assert rewards[0].item() == pytest.approx(-math.log(1 - 1 / (1 + math.exp(-2))), rel=1e-5)
    assert rewards[1].item() == pytest.approx(0.12693, rel=1e-4)
    assert rewards[2].item() == pytest.approx(math.log(2), rel=1e-6)


def test_calibrated_logit_is_invariant_to_the_critics_offset_and_scale() -> None:
    scores = torch.linspace(-3, 3, 7)
    base = calibrated_logit(scores, stats(2.0, -1.0, min_gap=0.1))
    moved = stats(7.0 * 2.0 - 40.0, 7.0 * -1.0 - 40.0, min_gap=0.1)
    drifted = calibrated_logit(7.0 * scores - 40.0, moved)
    torch.testing.assert_close(base, drifted, rtol=1e-5, atol=1e-5)


def test_calibrated_logit_flattens_when_the_critic_no_longer_separates() -> None:
    scores = torch.tensor([0.01, -0.01])
    logits = calibrated_logit(scores, stats(0.01, -0.01))
    np.testing.assert_allclose(logits.numpy(), [0.04, -0.04], rtol=1e-5)  # not ±2


def test_untrained_calibrated_reward_is_the_gail_form_of_the_critic() -> None:
    model = MCWAEWGAIL(OBS, ACT, K, reward_form="calibrated")
    reference = MCWAEWGAIL(OBS, ACT, K, reward_form="log1-d")
    reference.load_state_dict(model.state_dict())
    batch = synthetic(1.0, 16, seed=0)
    torch.testing.assert_close(model.reward(batch), reference.reward(batch))


def test_calibrated_reward_after_training_is_finite_bounded_and_anchored() -> None:
    expert, policy = synthetic(2.0, 400, seed=1), synthetic(-2.0, 400, seed=2)
    model, metrics = train(
        MCWAEWGAIL(OBS, ACT, K, reward_form="calibrated", batch_size=100), expert, policy, 20
    )
    last = metrics[-1]
    assert last["critic_expert"] > last["critic_policy"]
    # the logged spreads are the critic's own on either side (all 400 transitions scored)
    with torch.no_grad():
        spreads = [float(model.score(batch).std()) for batch in (expert, policy)]
    assert [last["critic_expert_std"], last["critic_policy_std"]] == pytest.approx(spreads)
    assert all(spread > 0 for spread in spreads)
    # the means of the rewards sit near the anchors (the GAIL form of ±2) whatever the gap
    assert last["reward_expert"] == pytest.approx(2.13, abs=0.5)
    assert last["reward_policy"] == pytest.approx(0.13, abs=0.1)
    for batch in (expert, policy):
        rewards = model.reward(batch)
        assert torch.isfinite(rewards).all() and (rewards >= 0).all()
    # the anchors travel with checkpoints
    clone = MCWAEWGAIL(OBS, ACT, K, reward_form="calibrated")
    clone.load_state_dict(model.state_dict())
    torch.testing.assert_close(clone.reward(expert), model.reward(expert))


def test_bonus_reports_learned_reward_and_bonus_per_training_step() -> None:
    expert, policy = synthetic(2.0, 200, seed=3), synthetic(-2.0, 200, seed=4)
    inner, _ = train(MCWAEWGAIL(OBS, ACT, K, batch_size=100), expert, policy, 1)
    model = ExplorationBonus(inner, weight=0.5)  # wrapped after Fabric's setup, as in a run
    rollout = as_rollout(policy, envs=4)
    learned = model.model.predict_reward(rollout)
    total = model.predict_reward(rollout, update=True)
    model.predict_reward(rollout)  # evaluation episodes do not count
    metrics = model.update(expert, policy, iteration=1)
    assert metrics["learned_per_step"] == pytest.approx(float(learned.mean()), rel=1e-5)
    assert metrics["bonus_per_step"] == pytest.approx(float((total - learned).mean()), rel=1e-5)
    assert 0.25 <= metrics["bonus_per_step"] < 0.5  # weight 0.5 × [1/2, 1)
    again = model.update(expert, policy, iteration=2)  # sums restart every iteration
    assert again["learned_per_step"] == 0.0 and again["bonus_per_step"] == 0.0


def test_standardized_logit_anchors_and_invariance() -> None:
    scores = torch.tensor([-3.0, -1.0, 1.0, 7.0])
    logits = standardized_logit(scores, stats(0.0, -1.0, policy_std=2.0))
    np.testing.assert_allclose(logits.numpy(), [-1.0, 0.0, 1.0, 4.0])
    # a critic that drifted by an offset and a scale gives the same logits
    moved = standardized_logit(5.0 + 3.0 * scores, stats(0.0, 2.0, policy_std=6.0))
    torch.testing.assert_close(moved, logits)


def test_standardized_reward_after_training_centres_the_policy() -> None:
    expert, policy = synthetic(2.0, 400, seed=5), synthetic(-2.0, 400, seed=6)
    model, metrics = train(
        MCWAEWGAIL(OBS, ACT, K, reward_form="standardized", batch_size=100), expert, policy, 20
    )
    last = metrics[-1]
    assert float(model.critic_policy_std) == pytest.approx(last["critic_policy_std"])
    rewards = model.reward(policy)
    assert torch.isfinite(rewards).all() and (rewards >= 0).all()
    # the policy's mean critic value sits at ℓ = 0: the mean logit over its data is 0
    with torch.no_grad():
        logits = (model.score(policy) - last["critic_policy"]) / last["critic_policy_std"]
    assert float(logits.mean()) == pytest.approx(0.0, abs=1e-4)
    assert float(logits.std()) == pytest.approx(1.0, abs=1e-4)
    # expert transitions, further up the critic, earn more than the policy's on average
    assert last["reward_expert"] > last["reward_policy"] > 0.5
    # σ_π travels with checkpoints; checkpoints without it load with σ_π = 1
    clone = MCWAEWGAIL(OBS, ACT, K, reward_form="standardized")
    clone.load_state_dict(model.state_dict())
    torch.testing.assert_close(clone.reward(expert), model.reward(expert))
    old = {k: v for k, v in model.state_dict().items() if k != "critic_policy_std"}
    clone.load_state_dict(old)
    assert float(clone.critic_policy_std) == 1.0
