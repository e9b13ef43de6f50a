"""The single-step archive exploration bonus (WQDIL, decision D5), as a reward wrapper.

r_exp(s) = 1 / (1 + p(δ(s))) with p(δ(s)) = n(C(δ(s))) / Σ_i n(C_i), where the cells C_i
of the single-step archive partition the space of single-step measures δ(s) and n counts
visits (the paper's Eqs. r_exp). With 0/1 foot-contact flags the cells are the 2^k contact
patterns; ``cells`` gives a finer grid over [0, 1]^k for continuous δ.

Visits count on training rollouts only (``predict_reward(..., update=True)``), step by
step: the bonus of step t uses the counts before step t's N visits are added, as in the
QD-IL code. Counts start at 1 per cell (so p is defined from the start), persist for the
whole run and go into checkpoints. The bonus lies in [weight/2, weight).
"""

from __future__ import annotations

from typing import Any

import torch
from typing_extensions import override

from qdil.data import Rollout, TransitionBatch
from qdil.demos.dataset import DemoSet
from qdil.rewards.base import RewardModel


class ExplorationBonus(RewardModel):
    """Adds the single-step archive bonus to any reward model.

    Forwards ``setup`` and ``update`` to the wrapped model; changes only the rewards
    handed to RL, so the wrapped model's training is untouched.

    Args:
        model: the wrapped reward model.
        weight: multiplier of r_exp (the paper: 1).
        cells: cells per measure; ``None`` for the 2^k binary contact patterns.
    """

    def __init__(self, model: RewardModel, weight: float = 1.0, cells: int | None = None) -> None:
        super().__init__(model.obs_dim, model.action_dim, model.num_measures)
        if cells is not None and cells < 1:
            raise ValueError(f"bonus.cells must be positive or null, got {cells}")
        self.model = model
        self.weight = weight
        self.cells = cells
        per_measure = 2 if cells is None else cells
        self.register_buffer(
            "counts", torch.ones(per_measure**model.num_measures, dtype=torch.float64)
        )
        # sums over this iteration's valid training steps: learned reward, bonus, steps
        self._balance = torch.zeros(3, dtype=torch.float64)
        self.name = f"{model.name}+bonus" if model.name else "bonus"
        self.learned = model.learned
        self.needs_demos = model.needs_demos
        self.needs_log_probs = model.needs_log_probs
        self.needs_next_obs = model.needs_next_obs
        self.uses_measures = model.uses_measures
        self.prefers_expert = model.prefers_expert

    def cell(self, measures: torch.Tensor) -> torch.Tensor:
        """(...,) single-step archive cell of δ (..., k)."""
        per_measure = 2 if self.cells is None else self.cells
        if self.cells is None:
            digits = (measures > 0.5).long()
        else:
            digits = (measures * self.cells).long().clamp(0, self.cells - 1)
        powers = per_measure ** torch.arange(measures.shape[-1])
        return (digits * powers).sum(-1)

    def bonus(self, rollout: Rollout, update: bool) -> torch.Tensor:
        """(T, N) r_exp of δ(s_t), counting the valid steps' visits if ``update``.

        Step t sees the counts before step t's visits are added. Rather than a Python loop
        over steps, the counts seen at every step are an exclusive cumulative sum of the
        per-step visits (T, cells): whole numbers in float64, so the result equals the
        step-by-step loop exactly.
        """
        cells = self.cell(rollout.contacts)  # (T, N)
        counts = self.counts.expand(rollout.num_steps, -1)  # (T, cells)
        if update:
            visits = torch.zeros(counts.shape, dtype=torch.float64)
            visits.scatter_add_(1, cells, (rollout.valid > 0).to(torch.float64))
            seen = visits.cumsum(0)
            counts = counts + torch.cat([torch.zeros_like(seen[:1]), seen[:-1]])
            self.counts += seen[-1]
        p = counts.gather(1, cells) / counts.sum(1, keepdim=True)
        return (1.0 / (1.0 + p)).float()

    @override
    def setup(self, demos: DemoSet | None) -> None:
        self.model.setup(demos)

    @override
    def pretrain(self, demos: DemoSet | None) -> None:
        self.model.pretrain(demos)

    @override
    def configure_optimizers(self) -> Any:
        return self.model.configure_optimizers()

    @override
    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        return self.model.reward(batch)

    @override
    def update(
        self, expert: TransitionBatch | None, policy: TransitionBatch, iteration: int
    ) -> dict[str, float]:
        metrics = self.model.update(expert, policy, iteration)
        share = self.counts / self.counts.sum()
        learned, bonus, steps = self._balance.tolist()
        self._balance.zero_()
        steps = max(steps, 1.0)
        return {
            **metrics,
            "learned_per_step": learned / steps,
            "bonus_per_step": bonus / steps,
            "bonus_min_share": float(share.min()),
            "bonus_max_share": float(share.max()),
        }

    @override
    @torch.no_grad()
    def predict_reward(self, rollout: Rollout, *, update: bool = False) -> torch.Tensor:
        base = self.model.predict_reward(rollout, update=update)
        bonus = self.weight * self.bonus(rollout, update)
        if update:  # the balance a user watches: learned reward and bonus per training step
            valid = rollout.valid > 0
            self._balance += torch.tensor(
                [float(base[valid].sum()), float(bonus[valid].sum()), float(valid.sum())],
                dtype=torch.float64,
            )
        return base + bonus

    @override
    def check_finite(self, value: torch.Tensor, what: str, iteration: int) -> None:
        # the bonus lies in [weight/2, weight): non-finite values come from the wrapped
        # model, which the message must name (with its own advice: learned or fixed)
        self.model.check_finite(value, what, iteration)

    @override
    def extra_state(self) -> dict[str, Any]:
        return self.model.extra_state()

    @override
    def load_extra_state(self, state: dict[str, Any]) -> None:
        self.model.load_extra_state(state)
