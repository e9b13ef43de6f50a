"""Extrinsic Behavioral Curiosity (EBC; Wan et al., ICML 2025), as a reward wrapper.

:class:`EBCBonus` adds p + q · 1[the rollout's mean measure falls in a cell of the CMA-MAE
archive that holds no elite] to every step of a training rollout; evaluations get the wrapped
model's rewards alone. Equations, the public code it follows, measurements: docs/rewards/ebc.md.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from ribs.archives import ArchiveBase
from typing_extensions import override

from qdil.data import Rollout
from qdil.rewards.base import RewardModel
from qdil.rewards.wrapper import BonusWrapper


class EBCBonus(BonusWrapper):
    """Adds the EBC bonus p + q·1[unoccupied] of each rollout window (``bonus.type: ebc``).

    Args:
        model: the wrapped reward model.
        archive: returns the archive whose occupancy decides novelty (the run's CMA-MAE
            archive). A function rather than the archive itself, because a resume replaces
            the archive object with the checkpoint's.
        weight: q, the bonus of a window in an unoccupied cell (the public runners: 2).
        offset: p, added to every training step whatever the cell (the public runners: 0).
    """

    def __init__(
        self,
        model: RewardModel,
        archive: Callable[[], ArchiveBase],
        weight: float = 2.0,
        offset: float = 0.0,
    ) -> None:
        super().__init__(model, weight, suffix="ebc")
        self.archive = archive
        self.offset = offset
        # windows in unoccupied cells and all windows since the last update, for the metrics
        self._windows = torch.zeros(2, dtype=torch.float64)

    @staticmethod
    def window_measures(rollout: Rollout) -> torch.Tensor:
        """(N, k) m̄: each simulation's mean δ(s_t) over the rollout's valid steps.

        A simulation without a valid step (only in padded evaluation rollouts, which get no
        bonus) has m̄ = 0.
        """
        valid = rollout.valid.unsqueeze(-1)  # (T, N, 1)
        total = (rollout.contacts * valid).sum(0)  # (N, k)
        return total / valid.sum(0).clamp_min(1.0)

    def unoccupied(self, measures: torch.Tensor) -> torch.Tensor:
        """(N,) True where m̄ (N, k) falls in a cell of the archive that holds no elite."""
        archive = self.archive()
        cells = archive.index_of(measures.double().cpu().numpy())  # pyribs: host
        occupied = np.isin(cells, archive.data("index"))
        return torch.from_numpy(~occupied).to(measures.device)

    def bonus(self, rollout: Rollout) -> torch.Tensor:
        """(T, N) float32 p + q·1[cell(m̄^n) unoccupied], the same at every step of column n."""
        novel = self.unoccupied(self.window_measures(rollout))
        self._windows += torch.tensor(
            [float(novel.sum()), float(novel.numel())], dtype=torch.float64
        )
        per_window = self.offset + self.weight * novel.to(torch.float32)  # (N,)
        return per_window.expand(rollout.num_steps, -1).clone()

    @override
    def added(self, rollout: Rollout, update: bool) -> torch.Tensor | None:
        # evaluation episodes get nothing: the archive ranks by the model's return alone
        return self.bonus(rollout) if update else None

    @override
    def bonus_metrics(self) -> dict[str, float]:
        novel, windows = self._windows.tolist()
        self._windows.zero_()
        # every iteration has training rollouts; without any there is no share to report
        return {"bonus_novel_share": novel / windows} if windows else {}
