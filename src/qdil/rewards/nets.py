"""Networks and losses shared by the reward models."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import torch
from torch import nn

from qdil.rewards.forms import log_one_minus_d


def mlp(
    in_dim: int,
    hidden: Sequence[int],
    out_dim: int,
    activation: type[nn.Module] = nn.Tanh,
) -> nn.Sequential:
    """A tanh MLP with Xavier-uniform weights (the QD-IL code's discriminator init).

    Args:
        in_dim: input size.
        hidden: hidden widths (the paper's discriminator: (100, 100)).
        out_dim: output size.
        activation: hidden activation.
    """
    sizes = [in_dim, *hidden, out_dim]
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        linear = nn.Linear(sizes[i], sizes[i + 1])
        nn.init.xavier_uniform_(linear.weight)
        nn.init.zeros_(linear.bias)
        layers.append(linear)
        if i < len(sizes) - 2:
            layers.append(activation())
    return nn.Sequential(*layers)


def gradient_penalty(
    critic: Callable[[torch.Tensor], torch.Tensor],
    real: torch.Tensor,
    fake: torch.Tensor,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """WGAN-GP's penalty E[(‖∇ₓ critic(x̂)‖₂ − 1)²] at x̂ = u·real + (1 − u)·fake.

    u ~ U(0, 1) per sample (Gulrajani et al. 2017; the QD-IL code drew u per element).

    Args:
        critic: maps (B, d) inputs to (B,) or (B, 1) scores.
        real: (B, d) expert inputs.
        fake: (B, d) policy inputs.
        generator: random source of u.
    """
    # drawn by the CPU generator (the same u on every device), used where the inputs live
    u = torch.rand((real.shape[0], 1), generator=generator, dtype=real.dtype).to(real.device)
    mixed = (u * real.detach() + (1 - u) * fake.detach()).requires_grad_(True)
    scores = critic(mixed)
    (grad,) = torch.autograd.grad(scores.sum(), mixed, create_graph=True)
    return (grad.norm(2, dim=1) - 1).square().mean()


def gail_reward(logits: torch.Tensor) -> torch.Tensor:
    """GAIL's reward −log(1 − σ(logit) + 1e-8): the ``log1-d`` reward form.

    ``1e-8`` caps the reward near 18.4 where σ(logit) → 1. Kept for plugins that compute
    their own reward; a model with a :meth:`score` gets it as ``reward_form: log1-d``.
    """
    return log_one_minus_d(logits)
