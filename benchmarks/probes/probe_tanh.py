"""What torch's float32 ``tanh`` costs PPO on this CPU, and what a vectorised one would save.

On the development VM (AMD EPYC with AVX-512, torch 2.13 CPU) ``torch.tanh`` runs at about
2.5 ns per float32 element, scalar speed, while numpy's vectorised ``tanh`` takes a
seventh of that. PPO's minibatch step calls it on every hidden layer of the stacked actors
and critics. This probe times one minibatch step of Walker2d's Jacobian phase (P = 3
policies, 512 samples each, actor 17-128-128-6, critic 17-256-256-1, Adam) with torch's
``tanh`` and with numpy's in its place, on one thread, and counts how many outputs differ.

numpy's ``tanh`` differs from torch's by at most one unit in the last place but not always
by zero, so the swap would change every trajectory: it is measured here, not used.

Usage::

    python benchmarks/probes/probe_tanh.py [--steps 200]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
import torch

from qdil.rl.networks import VectorizedActor, VectorizedCritic


class NumpyTanh(torch.autograd.Function):
    """tanh through numpy's vectorised float32 kernel; the backward is torch's."""

    @staticmethod
    def forward(ctx, x: torch.Tensor) -> torch.Tensor:
        # into a tensor torch allocated (64-byte aligned, as MKL's products want their inputs)
        y = torch.empty_like(x)
        np.tanh(x.detach().numpy(), out=y.numpy())
        ctx.save_for_backward(y)
        return y

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> torch.Tensor:
        (y,) = ctx.saved_tensors
        return torch.ops.aten.tanh_backward(grad, y)


def minibatch_step(steps: int) -> float:
    """Seconds per PPO minibatch step (forward, backward, clipping, Adam) of P = 3 policies."""
    generator = torch.Generator().manual_seed(0)
    actor = VectorizedActor(3, 17, 6)
    actor.initialize(generator, math.sqrt(2), 0.01)
    critic = VectorizedCritic(3, 17)
    optimizers = [torch.optim.Adam(m.parameters(), lr=1e-3, eps=1e-5) for m in (actor, critic)]
    obs, actions = torch.randn(3, 512, 17), torch.randn(3, 512, 6)
    old_log_probs, advantages, returns = (torch.randn(3, 512) for _ in range(3))

    def step() -> None:
        dist = actor.distribution(obs)
        ratio = (dist.log_prob(actions).sum(-1) - old_log_probs).exp()
        pg_loss = torch.max(-advantages * ratio, -advantages * ratio.clamp(0.8, 1.2)).mean(1)
        v_loss = 0.5 * (critic(obs) - returns).square().mean(1)
        loss = (pg_loss + 2.0 * v_loss).sum()
        for optimizer in optimizers:
            optimizer.zero_grad()
        loss.backward()
        actor.clip_grad_norm_per_model(1.0)
        critic.clip_grad_norm_per_model(1.0)
        for optimizer in optimizers:
            optimizer.step()

    for _ in range(20):
        step()
    start = time.perf_counter()
    for _ in range(steps):
        step()
    return (time.perf_counter() - start) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=200)
    args = parser.parse_args()
    torch.set_num_threads(1)
    x = torch.randn(3, 512, 256)
    for name, fn in (("torch.tanh", torch.tanh), ("np.tanh", lambda t: np.tanh(t.numpy()))):
        fn(x)
        start = time.perf_counter()
        for _ in range(200):
            fn(x)
        micros = (time.perf_counter() - start) / 200 * 1e6
        print(f"{name} on (3, 512, 256) float32: {micros:,.0f} us")
    ours, theirs = torch.tanh(x), torch.from_numpy(np.tanh(x.numpy()))
    ulp = (ours.view(torch.int32) - theirs.view(torch.int32)).abs().max().item()
    print(f"outputs that differ: {(ours != theirs).float().mean().item():.1%}, at most {ulp} ulp")
    with_torch = minibatch_step(args.steps)
    original = torch.tanh
    torch.tanh = NumpyTanh.apply  # the stacked MLPs look torch.tanh up at every call
    try:
        with_numpy = minibatch_step(args.steps)
    finally:
        torch.tanh = original
    print(
        f"PPO minibatch step, one thread: {with_torch * 1e3:.2f} ms with torch.tanh, "
        f"{with_numpy * 1e3:.2f} ms with numpy's ({with_numpy / with_torch:.2f}x)"
    )


if __name__ == "__main__":
    main()
