from __future__ import annotations

import numpy as np
import torch

from qdil.rl.gae import compute_gae
from qdil.rl.normalize import RunningMeanStd


def naive_gae(rewards, values, next_values, dones, terminated, gamma, lam):
    steps, n = rewards.shape
    adv = np.zeros((steps, n))
    for i in range(n):
        running = 0.0
        for t in reversed(range(steps)):
            delta = (
                rewards[t, i] + gamma * (1 - terminated[t, i]) * next_values[t, i] - values[t, i]
            )
            running = delta + gamma * lam * (1 - dones[t, i]) * running
            adv[t, i] = running
    return adv


def test_gae_matches_the_textbook_recursion(rng) -> None:
    steps, n = 20, 5
    rewards, values, next_values = (rng.normal(size=(steps, n)) for _ in range(3))
    dones = (rng.random((steps, n)) < 0.2).astype(float)
    terminated = dones * (rng.random((steps, n)) < 0.5)
    expected = naive_gae(rewards, values, next_values, dones, terminated, 0.99, 0.95)
    t = [torch.tensor(x) for x in (rewards, values, next_values, dones, terminated)]
    advantages, returns = compute_gae(*t, gamma=0.99, gae_lambda=0.95)
    np.testing.assert_allclose(advantages.numpy(), expected, rtol=1e-12)
    np.testing.assert_allclose(returns.numpy(), expected + values, rtol=1e-12)


def test_gae_truncation_bootstraps_and_termination_does_not() -> None:
    one = torch.ones(1, 1)
    truncated, _ = compute_gae(one, 0 * one, 10 * one, one, 0 * one, gamma=0.5, gae_lambda=1.0)
    terminated, _ = compute_gae(one, 0 * one, 10 * one, one, one, gamma=0.5, gae_lambda=1.0)
    assert truncated.item() == 1 + 0.5 * 10
    assert terminated.item() == 1


def test_running_mean_std_equals_numpy_over_batches(rng) -> None:
    stats = RunningMeanStd(2, (3,), epsilon=0.0)
    batches = [
        rng.normal(loc=[[[1.0]], [[-5.0]]], scale=2.0, size=(2, size, 3)) for size in (7, 50, 1)
    ]
    for batch in batches:
        stats.update(torch.tensor(batch))
    everything = np.concatenate(batches, axis=1)
    np.testing.assert_allclose(stats.mean.numpy(), everything.mean(1), rtol=1e-10)
    np.testing.assert_allclose(stats.var.numpy(), everything.var(1), rtol=1e-10)
    np.testing.assert_allclose(stats.count.numpy(), [58, 58])


def test_normalize_is_per_policy_and_invertible(rng) -> None:
    stats = RunningMeanStd(2, (4,))
    stats.update(torch.tensor(rng.normal(loc=[[[3.0]], [[-3.0]]], size=(2, 1000, 4))))
    x = torch.tensor(rng.normal(size=(2, 10, 4)))
    normalized = stats.normalize(x)
    assert normalized[0].mean() < -2 and normalized[1].mean() > 2
    np.testing.assert_allclose(stats.denormalize(normalized).numpy(), x.numpy(), rtol=1e-10)
    assert stats.normalize(x * 1e6, clip=5.0).abs().max() == 5.0


def test_fresh_statistics_start_at_zero_mean_unit_variance() -> None:
    stats = RunningMeanStd(1, (2,))
    assert stats.mean.dtype == torch.float64
    np.testing.assert_array_equal(stats.mean.numpy(), 0.0)
    np.testing.assert_array_equal(stats.var.numpy(), 1.0)


def test_one_policys_statistics_are_the_same_with_one_and_two_threads(at_threads) -> None:
    """The walk's value targets: one mean and one variance over every step of the rollout."""
    x = torch.randn(1, 40000, dtype=torch.float64, generator=torch.Generator().manual_seed(0))

    def updated() -> RunningMeanStd:
        stats = RunningMeanStd(1)
        stats.update(x * 3 + 1)
        return stats

    one, two = at_threads(1, updated), at_threads(2, updated)
    assert torch.equal(one.mean, two.mean) and torch.equal(one.var, two.var)
