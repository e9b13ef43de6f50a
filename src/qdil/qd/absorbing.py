"""What the absorbing state after a termination adds to the returns the loop hands out.

A reward model with ``absorbing`` on learns r_a, the per-step reward of the absorbing
state an episode enters where it terminates and never leaves (DAC). :class:`AbsorbingTail`
adds that state's worth at each terminated step: r_a·γ/(1 − γ) for an estimator that
discounts per-step rewards (VPPO's GAE then bootstraps from the absorbing state's value
instead of zero), and r_a·(H − t) for whole-episode returns up to the time limit H (the
archive's objective, ES gradients). Why: docs/concepts/absorbing.md.
"""

from __future__ import annotations

import torch

from qdil.data import Rollout
from qdil.rewards.base import RewardModel


class AbsorbingTail:
    """The absorbing state's worth at the terminated steps of a rollout, (T, N).

    Args:
        reward: a model with ``absorbing`` on.
        horizon: H, the episodes' time limit.
        gamma: the estimator's discount: r_a·γ/(1 − γ) at each termination; ``None``:
            r_a·(H − t), for rollouts whose columns each hold one episode from its first
            step (evaluations), so a terminated episode scores as one lasting to the limit.
        iteration: the QD iteration, for error messages.

    Attributes:
        total: the sum of r_a over the terminated steps seen (its mean is logged).
        count: how many terminated steps were seen.
    """

    def __init__(
        self, reward: RewardModel, horizon: int, gamma: float | None, iteration: int
    ) -> None:
        self.reward, self.horizon, self.gamma = reward, horizon, gamma
        self.iteration = iteration
        self.total, self.count = 0.0, 0

    def __call__(self, rollout: Rollout) -> torch.Tensor:
        """(T, N) the absorbing state's worth at ``rollout``'s terminated steps, else 0."""
        ended = (rollout.terminated * rollout.valid) > 0
        out = torch.zeros(rollout.rewards.shape, device=rollout.rewards.device)
        if not bool(ended.any()):
            return out
        values = self.reward.absorbing_reward(rollout.flat()[ended.reshape(-1)]).float()
        self.reward.check_finite(values, "absorbing-state rewards", self.iteration)
        self.total += float(values.double().sum())
        self.count += int(values.numel())
        if self.gamma is not None:
            weights = torch.full_like(values, self.gamma / (1.0 - self.gamma))
        else:  # the episode's length at each step, where it terminated
            steps = torch.cumsum(rollout.valid, dim=0)[ended]
            weights = (self.horizon - steps).clamp_min(0.0)
        out[ended] = values * weights
        return out

    @property
    def mean(self) -> float:
        """Mean r_a over the terminated steps seen (NaN when none terminated)."""
        return self.total / self.count if self.count else float("nan")
