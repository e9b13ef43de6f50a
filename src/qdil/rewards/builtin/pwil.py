"""``pwil``: Primal Wasserstein Imitation Learning (Dadashi et al., ICLR 2021).

:class:`PWIL`, an offline reward: each episode's steps are transported greedily onto the
demonstrations, and a step that lands close to still-unused expert mass earns a high reward,
r_t = α exp(−β T c_t / √d). Equations and the per-simulation pools: docs/rewards/pwil.md.
"""

from __future__ import annotations

import math
from typing import Any

import torch
from typing_extensions import override

from qdil.data import Rollout, TransitionBatch
from qdil.demos.dataset import DemoSet
from qdil.rewards.base import RewardModel
from qdil.rewards.registry import register_reward


@register_reward("pwil")
class PWIL(RewardModel):
    """PWIL: greedy Wasserstein coupling to the expert's atoms, per episode.

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        alpha: reward scale α.
        beta: bandwidth β.
        horizon: T, the episode horizon that sets each agent atom's weight 1/T.
        use_actions: atoms are (s, a) (default) or s alone.
    """

    description = "PWIL (Dadashi et al. 2021): offline greedy-Wasserstein reward"
    learned = False

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        alpha: float = 5.0,
        beta: float = 5.0,
        horizon: int = 1000,
        use_actions: bool = True,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures)
        if horizon < 1:
            raise ValueError(f"pwil: horizon must be positive, got {horizon}")
        self.alpha, self.beta, self.horizon, self.use_actions = alpha, beta, horizon, use_actions
        self.register_buffer("atoms", torch.zeros(0, self.atom_dim))
        self._pools: torch.Tensor | None = None

    @property
    def atom_dim(self) -> int:
        """Atom size d."""
        return self.obs_dim + (self.action_dim if self.use_actions else 0)

    def embed(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """(B, d) standardised atoms."""
        parts = [self.normalize_obs(obs)]
        if self.use_actions:
            parts.append(self.normalize_actions(actions))
        return torch.cat(parts, dim=-1)

    @override
    def setup(self, demos: DemoSet | None) -> None:
        super().setup(demos)
        if demos is None:
            raise ValueError("pwil needs demonstrations (demos.path)")
        batch = demos.transitions()
        self.atoms = self.embed(batch.obs, batch.actions)

    @override
    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        raise NotImplementedError("pwil's reward depends on the episode so far: use predict_reward")

    def step_costs(self, x: torch.Tensor, pools: torch.Tensor) -> torch.Tensor:
        """Transport one agent atom per environment; returns (N,) costs, updates ``pools``.

        Args:
            x: (N, d) agent atoms of one time step.
            pools: (N, D) remaining expert weights, modified in place.
        """
        distances = torch.cdist(x, self.atoms.to(x.dtype))
        left = torch.full((len(x),), 1.0 / self.horizon, dtype=pools.dtype)
        cost = torch.zeros(len(x), dtype=pools.dtype)
        rows = torch.arange(len(x))
        while bool((left > 1e-12).any()) and bool((pools.sum(1) > 1e-12).any()):
            masked = torch.where(pools > 1e-12, distances, torch.full_like(distances, math.inf))
            nearest = masked.argmin(1)
            moved = torch.minimum(left, pools[rows, nearest])
            moved = torch.where(
                torch.isfinite(masked[rows, nearest]), moved, torch.zeros_like(moved)
            )
            if not bool((moved > 0).any()):
                break
            cost += moved * distances[rows, nearest]
            pools[rows, nearest] -= moved
            left -= moved
        return cost

    @override
    @torch.no_grad()
    def predict_reward(self, rollout: Rollout, *, update: bool = False) -> torch.Tensor:
        steps, n = rollout.rewards.shape
        full = torch.full((n, len(self.atoms)), 1.0 / len(self.atoms), dtype=torch.float64)
        pools = (
            self._pools
            if update and self._pools is not None and self._pools.shape[0] == n
            else None
        )
        pools = full.clone() if pools is None else pools
        scale = self.beta * self.horizon / math.sqrt(self.atom_dim)
        rewards = torch.zeros(steps, n)
        for t in range(steps):
            starts = rollout.starts[t] > 0
            pools[starts] = full[starts]
            x = self.embed(rollout.obs[t], rollout.actions[t]).double()
            cost = self.step_costs(x, pools)
            rewards[t] = (self.alpha * torch.exp(-scale * cost)).float()
        if update:
            self._pools = pools
        return rewards

    @override
    def extra_state(self) -> dict[str, Any]:
        return {"pools": None if self._pools is None else self._pools.clone()}

    @override
    def load_extra_state(self, state: dict[str, Any]) -> None:
        self._pools = state.get("pools")
