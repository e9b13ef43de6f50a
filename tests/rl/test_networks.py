from __future__ import annotations

from functools import partial

import numpy as np
import pytest
import torch
from torch import nn

from qdil.rl.networks import VectorizedActor, VectorizedCritic


def single_mlp(solution: np.ndarray, sizes: list[int]) -> tuple[nn.Sequential, torch.Tensor]:
    """A plain torch MLP loaded from a flat solution, in the documented layout."""
    layers, offset = [], 0
    flat = torch.tensor(solution)
    for i in range(len(sizes) - 1):
        linear = nn.Linear(sizes[i], sizes[i + 1])
        with torch.no_grad():
            for p in (linear.weight, linear.bias):
                p.copy_(flat[offset : offset + p.numel()].reshape(p.shape))
                offset += p.numel()
        layers += [linear, nn.Tanh()]
    return nn.Sequential(*layers[:-1]), flat[offset:]


def test_vectorized_actor_equals_a_loop_of_single_policies(rng) -> None:
    obs_dim, action_dim, num = 17, 6, 5
    dim = VectorizedActor.solution_dim(obs_dim, action_dim)
    solutions = rng.normal(scale=0.1, size=(num, dim)).astype(np.float32)
    actor = VectorizedActor(num, obs_dim, action_dim)
    actor.set_solutions(solutions)
    obs = torch.tensor(rng.normal(size=(num, 32, obs_dim)), dtype=torch.float32)
    with torch.no_grad():
        batched = actor(obs)
        for i in range(num):
            mlp, log_std = single_mlp(solutions[i], [obs_dim, 128, 128, action_dim])
            torch.testing.assert_close(batched[i], mlp(obs[i]), rtol=1e-5, atol=1e-6)
            torch.testing.assert_close(actor.log_std[i], log_std)


def test_solution_round_trip_and_shape_check(rng) -> None:
    dim = VectorizedActor.solution_dim(11, 3, (8, 8))
    assert dim == 11 * 8 + 8 + 8 * 8 + 8 + 8 * 3 + 3 + 3
    solutions = rng.normal(size=(2, dim)).astype(np.float32)
    actor = VectorizedActor(2, 11, 3, (8, 8))
    actor.set_solutions(solutions)
    np.testing.assert_array_equal(actor.get_solutions(), solutions)
    with pytest.raises(ValueError, match=r"shape \(2, 198\), got \(2, 197\)"):
        actor.set_solutions(solutions[:, :-1])


def test_initial_solution_follows_ppga() -> None:
    theta = VectorizedActor.initial_solution(17, 6, seed=3)
    actor = VectorizedActor(1, 17, 6)
    actor.set_solutions(theta[None])
    actor.requires_grad_(False)
    first, last = actor.weights[0][0], actor.weights[-1][0]
    # semi-orthogonal matrices scaled by the gain: √2 for hidden layers, 0.01 for the last
    torch.testing.assert_close(first.T @ first, 2 * torch.eye(17), atol=1e-4, rtol=0)
    torch.testing.assert_close(last @ last.T, 1e-4 * torch.eye(6), atol=1e-7, rtol=0)
    assert all(float(b.abs().max()) == 0 for b in actor.biases)
    assert float(actor.log_std.abs().max()) == 0
    np.testing.assert_array_equal(theta, VectorizedActor.initial_solution(17, 6, seed=3))


def test_per_policy_gradient_clipping_leaves_small_gradients_alone() -> None:
    critic = VectorizedCritic(2, 4, (8,))
    obs = torch.randn(2, 16, 4)
    scale = torch.tensor([1e3, 1e-3])[:, None]
    (critic(obs) * scale).sum().backward()
    before = [p.grad[1].clone() for p in critic.parameters()]
    norms = critic.clip_grad_norm_per_model(1.0)
    after = torch.sqrt(sum(p.grad[0].square().sum() for p in critic.parameters()))
    assert norms[0] > 1 and abs(float(after) - 1.0) < 1e-4
    for b, p in zip(before, critic.parameters(), strict=True):
        torch.testing.assert_close(p.grad[1], b)


def test_per_model_gradient_clipping_is_the_same_with_one_and_two_threads(at_threads) -> None:
    """One critic's 256 x 256 layer sums 65,536 squares into its norm: once split by thread."""

    critic = VectorizedCritic(1, 17)

    def clipped(seed: int) -> list[torch.Tensor]:
        g = torch.Generator().manual_seed(seed)
        for p in critic.parameters():
            p.grad = torch.randn(p.shape, generator=g)
        norms = critic.clip_grad_norm_per_model(1.0)
        return [norms, *(p.grad.clone() for p in critic.parameters())]

    for seed in range(10):  # seed 6's norm differed in the last bit before
        one, two = (at_threads(n, partial(clipped, seed)) for n in (1, 2))
        assert all(torch.equal(a, b) for a, b in zip(one, two, strict=True)), seed


def test_a_lone_bias_gradient_is_the_same_with_one_and_two_threads(at_threads) -> None:
    """One critic's one-output head sums its bias gradient over every row of a batch."""
    critic = VectorizedCritic(1, 17, hidden=(8, 8))
    obs = torch.randn(1, 40000, 17, generator=torch.Generator().manual_seed(0))

    def gradients() -> list[torch.Tensor]:
        critic.zero_grad()
        critic(obs).square().mean().backward()
        return [p.grad.clone() for p in critic.parameters()]

    one, two = at_threads(1, gradients), at_threads(2, gradients)
    assert all(torch.equal(a, b) for a, b in zip(one, two, strict=True))
    with torch.no_grad():  # the plain broadcast, as in every forward pass without gradients
        plain = critic(obs)
    assert torch.equal(critic(obs).detach(), plain)
