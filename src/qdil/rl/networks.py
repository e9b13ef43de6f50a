"""P policies (or critics) evaluated together with batched matrix products.

A policy is one flat *solution* vector for pyribs: the MLP's weights and biases in layer
order (each ``weight`` row-major as in ``torch.nn.Linear``, then its ``bias``), followed by
the log standard deviations. :class:`VectorizedActor` stacks P such solutions and runs them
on a (P, B, obs_dim) batch with ``torch.baddbmm``, so the k+1 gradient copies of VPPO and the
λ branched solutions share one forward pass. The actor works on *normalised* observations;
normalisation statistics travel beside the solution (see :mod:`qdil.rl.normalize`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

from qdil.reductions import GRAIN_SIZE, sum_over


def _layer_shapes(sizes: Sequence[int]) -> list[tuple[int, int]]:
    return [(sizes[i + 1], sizes[i]) for i in range(len(sizes) - 1)]


def _orthogonal(out_dim: int, in_dim: int, gain: float, generator: torch.Generator) -> torch.Tensor:
    """An orthogonal (out_dim, in_dim) matrix scaled by ``gain`` (as ``nn.init.orthogonal_``)."""
    rows, cols = out_dim, in_dim
    flat = torch.randn(max(rows, cols), min(rows, cols), generator=generator, dtype=torch.float64)
    q, r = torch.linalg.qr(flat)
    q = q * torch.sign(torch.diagonal(r)).unsqueeze(0)
    if rows < cols:
        q = q.T
    return (gain * q[:rows, :cols]).to(torch.float32)


class _RowBias(torch.autograd.Function):
    """A (P, 1, out) bias broadcast to (P, B, out), its gradient summed by :func:`sum_over`.

    Autograd sums a broadcast bias's gradient over the B rows; with one policy and one output
    (the walk's critic head) that sum has a single output, split between threads from
    :data:`GRAIN_SIZE` rows on (a paper minibatch has 48,000), so its rounding would follow
    the thread count. :func:`sum_over` gives it the one-thread bits.
    """

    @staticmethod
    def forward(ctx, bias: torch.Tensor, rows: int) -> torch.Tensor:
        return bias.expand(bias.shape[0], rows, bias.shape[2])

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        return sum_over(grad, 1, keepdim=True), None


def _lone_bias_grad(bias: torch.Tensor, rows: int) -> bool:
    """Whether autograd would sum ``bias``'s gradient into one element split between threads."""
    return (
        bias.numel() == 1
        and rows >= GRAIN_SIZE
        and bias.requires_grad
        and bias.device.type == "cpu"
    )


class _StackedMLP(nn.Module):
    """P independent MLPs with tanh hidden layers, parameters stacked on a leading axis."""

    def __init__(self, num_models: int, sizes: Sequence[int]) -> None:
        super().__init__()
        self.sizes = list(sizes)
        shapes = _layer_shapes(self.sizes)
        self.weights = nn.ParameterList(
            [nn.Parameter(torch.zeros(num_models, out, inp)) for out, inp in shapes]
        )
        self.biases = nn.ParameterList(
            [nn.Parameter(torch.zeros(num_models, out)) for out, _ in shapes]
        )

    @property
    def num_models(self) -> int:
        """P."""
        return self.weights[0].shape[0]

    def operands(self) -> list[tuple[torch.Tensor, torch.Tensor]]:
        """Per layer, the (P, 1, out) bias and (P, in, out) weightᵀ views :meth:`mlp` uses."""
        return [
            (bias.unsqueeze(1), weight.transpose(1, 2))
            for weight, bias in zip(self.weights, self.biases, strict=True)
        ]

    def mlp(
        self, x: torch.Tensor, operands: list[tuple[torch.Tensor, torch.Tensor]] | None = None
    ) -> torch.Tensor:
        """(P, B, sizes[0]) -> (P, B, sizes[-1]).

        Args:
            x: (P, B, sizes[0]) inputs.
            operands: :meth:`operands`, taken once by callers that run many small batches
                with fixed parameters (iterating the parameter lists costs more than a small
                layer's product); ``None`` takes them now.
        """
        layers = self.operands() if operands is None else operands
        last = len(layers) - 1
        grad = torch.is_grad_enabled()  # once: rollouts call this every step, without gradients
        for i, (bias, weight_t) in enumerate(layers):
            if grad and _lone_bias_grad(bias, x.shape[1]):
                bias = _RowBias.apply(bias, x.shape[1])  # same forward; one-thread bits backward
            x = torch.baddbmm(bias, x, weight_t)
            if i < last:
                x = torch.tanh(x)
        return x

    def initialize(self, generator: torch.Generator, hidden_gain: float, last_gain: float) -> None:
        """Orthogonal weights (CleanRL/PPGA): gain √2 on hidden layers, ``last_gain`` last."""
        with torch.no_grad():
            last = len(self.weights) - 1
            for i, weight in enumerate(self.weights):
                gain = last_gain if i == last else hidden_gain
                for p in range(weight.shape[0]):
                    weight[p] = _orthogonal(weight.shape[1], weight.shape[2], gain, generator)
            for bias in self.biases:
                bias.zero_()

    def clip_grad_norm_per_model(self, max_norm: float) -> torch.Tensor:
        """Clip each model's gradient to ``max_norm`` separately; returns (P,) norms."""
        grads = [p.grad for p in self.parameters() if p.grad is not None]
        if not grads:
            return torch.zeros(self.num_models, device=self.weights[0].device)
        # one model's squared norm of a 256 x 256 layer sums 65,536 numbers into one: the sum
        # whose split between threads would change the clipping's last bits
        norms = torch.sqrt(sum(sum_over(g.reshape(g.shape[0], -1).square(), 1) for g in grads))
        scale = (max_norm / (norms + 1e-6)).clamp(max=1.0)
        for g in grads:
            g.mul_(scale.reshape(-1, *([1] * (g.dim() - 1))))
        return norms


class VectorizedActor(_StackedMLP):
    """P diagonal-Gaussian MLP policies with state-independent standard deviations.

    Args:
        num_policies: P.
        obs_dim: observation size.
        action_dim: action size.
        hidden: hidden layer widths (the paper: (128, 128)).
    """

    def __init__(
        self, num_policies: int, obs_dim: int, action_dim: int, hidden: Sequence[int] = (128, 128)
    ) -> None:
        super().__init__(num_policies, [obs_dim, *hidden, action_dim])
        self.log_std = nn.Parameter(torch.zeros(num_policies, action_dim))

    @staticmethod
    def solution_dim(obs_dim: int, action_dim: int, hidden: Sequence[int] = (128, 128)) -> int:
        """Length D of one policy's flat solution vector."""
        shapes = _layer_shapes([obs_dim, *hidden, action_dim])
        return sum(out * inp + out for out, inp in shapes) + action_dim

    @classmethod
    def initial_solution(
        cls,
        obs_dim: int,
        action_dim: int,
        hidden: Sequence[int] = (128, 128),
        seed: int = 0,
    ) -> np.ndarray:
        """(D,) float32 solution with PPGA's initialisation (last-layer gain 0.01, log σ 0)."""
        actor = cls(1, obs_dim, action_dim, hidden)
        actor.initialize(torch.Generator().manual_seed(seed), math.sqrt(2), 0.01)
        return actor.get_solutions()[0]

    def get_solutions(self) -> np.ndarray:
        """(P, D) float32 flat solution vectors."""
        parts = []
        for weight, bias in zip(self.weights, self.biases, strict=True):
            parts += [weight.detach().reshape(self.num_models, -1), bias.detach()]
        parts.append(self.log_std.detach())
        return torch.cat(parts, dim=1).cpu().numpy().astype(np.float32)

    def set_solutions(self, solutions: np.ndarray | torch.Tensor) -> None:
        """Load (P, D) flat solution vectors into the stacked parameters.

        Raises:
            ValueError: if the shape does not match (P, D).
        """
        flat = torch.as_tensor(np.asarray(solutions), dtype=torch.float32)
        dim = self.solution_dim(self.sizes[0], self.sizes[-1], self.sizes[1:-1])
        if flat.shape != (self.num_models, dim):
            raise ValueError(
                f"solutions must have shape {(self.num_models, dim)}, got {tuple(flat.shape)}"
            )
        offset = 0
        with torch.no_grad():
            for weight, bias in zip(self.weights, self.biases, strict=True):
                for tensor in (weight, bias):
                    size = tensor[0].numel()
                    tensor.copy_(flat[:, offset : offset + size].reshape(tensor.shape))
                    offset += size
            self.log_std.copy_(flat[:, offset:])

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """(P, B, obs_dim) normalised observations -> (P, B, action_dim) action means."""
        return self.mlp(obs)

    def distribution(self, obs: torch.Tensor) -> torch.distributions.Normal:
        """The (P, B, action_dim) diagonal Gaussian at normalised observations ``obs``."""
        mean = self.mlp(obs)
        return torch.distributions.Normal(mean, self.log_std.exp().unsqueeze(1).expand_as(mean))


class VectorizedCritic(_StackedMLP):
    """P value functions V(s), one per objective or policy.

    Args:
        num_heads: P.
        obs_dim: observation size.
        hidden: hidden layer widths (the paper: (256, 256)).
        seed: initialisation seed.
    """

    def __init__(
        self, num_heads: int, obs_dim: int, hidden: Sequence[int] = (256, 256), seed: int = 0
    ) -> None:
        super().__init__(num_heads, [obs_dim, *hidden, 1])
        self.initialize(torch.Generator().manual_seed(seed), math.sqrt(2), 1.0)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """(P, B, obs_dim) normalised observations -> (P, B) values."""
        return self.mlp(obs).squeeze(-1)
