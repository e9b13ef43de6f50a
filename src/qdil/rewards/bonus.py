"""The single-step archive exploration bonus (WQDIL, decision D5), as a reward wrapper.

:class:`ExplorationBonus` adds w / (1 + p(δ(s))) to any reward model's rewards, p the share of
training visits that fell in δ(s)'s cell of the single-step archive. Equations, the counting
rule and measurements: docs/rewards/bonus.md.
"""

from __future__ import annotations

import torch
from typing_extensions import override

from qdil.data import Rollout
from qdil.rewards.base import RewardModel
from qdil.rewards.wrapper import BonusWrapper


class ExplorationBonus(BonusWrapper):
    """Adds the single-step archive bonus to any reward model (``bonus.type: single_step``).

    Forwards ``setup`` and ``update`` to the wrapped model; changes only the rewards
    handed to RL and to the evaluations, so the wrapped model's training is untouched.

    Args:
        model: the wrapped reward model.
        weight: multiplier of r_exp (the paper: 1).
        cells: cells per measure; ``None`` for the 2^k binary contact patterns.
        in_fitness: add the bonus to evaluation episodes too, so that the archive ranks by
            learned return + bonus (the paper); ``False``: training rollouts only.
    """

    def __init__(
        self,
        model: RewardModel,
        weight: float = 1.0,
        cells: int | None = None,
        in_fitness: bool = True,
    ) -> None:
        super().__init__(model, weight, suffix="bonus")
        self.in_fitness = in_fitness
        if cells is not None and cells < 1:
            raise ValueError(f"bonus.cells must be positive or null, got {cells}")
        self.cells = cells
        per_measure = 2 if cells is None else cells
        self.register_buffer(
            "counts", torch.ones(per_measure**model.num_measures, dtype=torch.float64)
        )

    def cell(self, measures: torch.Tensor) -> torch.Tensor:
        """(...,) single-step archive cell of δ (..., k)."""
        per_measure = 2 if self.cells is None else self.cells
        if self.cells is None:
            digits = (measures > 0.5).long()
        else:
            digits = (measures * self.cells).long().clamp(0, self.cells - 1)
        powers = per_measure ** torch.arange(measures.shape[-1], device=measures.device)
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
            visits = torch.zeros(counts.shape, dtype=torch.float64, device=counts.device)
            visits.scatter_add_(1, cells, (rollout.valid > 0).to(torch.float64))
            seen = visits.cumsum(0)
            counts = counts + torch.cat([torch.zeros_like(seen[:1]), seen[:-1]])
            self.counts += seen[-1]
        p = counts.gather(1, cells) / counts.sum(1, keepdim=True)
        return (1.0 / (1.0 + p)).float()

    @override
    def added(self, rollout: Rollout, update: bool) -> torch.Tensor | None:
        # evaluations get the bonus too (from the current counts, adding no visits): the
        # archive ranks by learned return + bonus, as the WQDIL paper's algorithm does;
        # without in_fitness the archive sees the learned reward alone
        if not update and not self.in_fitness:
            return None
        return self.weight * self.bonus(rollout, update)

    @override
    def bonus_metrics(self) -> dict[str, float]:
        share = self.counts / self.counts.sum()
        return {"bonus_min_share": float(share.min()), "bonus_max_share": float(share.max())}
