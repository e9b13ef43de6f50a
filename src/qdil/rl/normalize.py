"""Running mean and variance, one set of statistics per policy.

PPGA normalises observations per policy (each archive elite carries its own statistics) and
normalises value targets per objective. Both use :class:`RunningMeanStd` with a leading
policy axis P. Quirk Q1 of PPGA's code (mean initialised to 1, float32) is not copied: the
mean starts at 0, the variance at 1, the count at a tiny epsilon, in float64.
"""

from __future__ import annotations

import numpy as np
import torch

from qdil.reductions import mean_over, var_over


class RunningMeanStd:
    """Per-policy running statistics of vectors, merged with Chan et al.'s parallel update.

    Args:
        num_policies: P, the number of independent statistics.
        shape: shape of one sample, e.g. ``(obs_dim,)`` or ``()``.
        epsilon: initial count, so that the first batch dominates.
        device: where the statistics live (the run's device).

    Attributes:
        mean: (P, *shape) float64.
        var: (P, *shape) float64.
        count: (P,) float64.
    """

    def __init__(
        self,
        num_policies: int,
        shape: tuple[int, ...] = (),
        epsilon: float = 1e-4,
        device: torch.device | str | None = None,
    ) -> None:
        on = {"dtype": torch.float64, "device": device}
        self.mean = torch.zeros((num_policies, *shape), **on)
        self.var = torch.ones((num_policies, *shape), **on)
        self.count = torch.full((num_policies,), epsilon, **on)

    @property
    def device(self) -> torch.device:
        """Where the statistics live."""
        return self.mean.device

    def to(self, device: torch.device | str) -> RunningMeanStd:
        """These statistics on ``device`` (``self`` if they are there already)."""
        if self.mean.device == torch.device(device):
            return self
        out = RunningMeanStd.__new__(RunningMeanStd)
        out.mean, out.var, out.count = (x.to(device) for x in (self.mean, self.var, self.count))
        return out

    @property
    def num_policies(self) -> int:
        """P."""
        return self.mean.shape[0]

    def update(self, x: torch.Tensor) -> None:
        """Merge a batch per policy.

        Args:
            x: (P, B, *shape) samples; policy i's statistics absorb ``x[i]``.
        """
        x = x.detach().to(torch.float64)
        # one policy's scalar statistics (the walk's value targets: 384,000 at paper scale)
        # reduce to one number each, which torch would split between threads
        batch_mean = mean_over(x, 1)
        batch_var = var_over(x, 1, correction=0)
        batch_count = torch.full_like(self.count, x.shape[1])
        delta = batch_mean - self.mean
        total = self.count + batch_count
        expand = (slice(None),) + (None,) * (self.mean.dim() - 1)
        self.mean = self.mean + delta * (batch_count / total)[expand]
        m2 = (
            self.var * self.count[expand]
            + batch_var * batch_count[expand]
            + delta.square() * (self.count * batch_count / total)[expand]
        )
        self.var = m2 / total[expand]
        self.count = total

    def normalize(self, x: torch.Tensor, clip: float | None = None) -> torch.Tensor:
        """(x - mean) / sqrt(var + 1e-8) per policy, optionally clipped to ±clip.

        Args:
            x: (P, B, *shape) values.
            clip: bound of the result, or ``None``.
        """
        mean = self.mean.to(x.dtype).unsqueeze(1)
        std = torch.sqrt(self.var + 1e-8).to(x.dtype).unsqueeze(1)
        out = (x - mean) / std
        return out.clamp(-clip, clip) if clip is not None else out

    def denormalize(self, x: torch.Tensor) -> torch.Tensor:
        """Inverse of :meth:`normalize` without clipping; x is (P, B, *shape)."""
        mean = self.mean.to(x.dtype).unsqueeze(1)
        std = torch.sqrt(self.var + 1e-8).to(x.dtype).unsqueeze(1)
        return x * std + mean

    def select(self, index: list[int] | torch.Tensor) -> RunningMeanStd:
        """A copy holding the statistics of policies ``index``."""
        out = RunningMeanStd.__new__(RunningMeanStd)
        out.mean = self.mean[index].clone()
        out.var = self.var[index].clone()
        out.count = self.count[index].clone()
        return out

    def state_dict(self) -> dict[str, torch.Tensor]:
        """The statistics, for checkpoints."""
        return {"mean": self.mean.clone(), "var": self.var.clone(), "count": self.count.clone()}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        """Restore :meth:`state_dict`."""
        self.mean, self.var, self.count = state["mean"], state["var"], state["count"]

    @classmethod
    def stack(cls, stats: list[RunningMeanStd]) -> RunningMeanStd:
        """Concatenate statistics along P."""
        out = cls.__new__(cls)
        out.mean = torch.cat([s.mean for s in stats])
        out.var = torch.cat([s.var for s in stats])
        out.count = torch.cat([s.count for s in stats])
        return out


def stats_from_fields(fields: dict[str, np.ndarray]) -> RunningMeanStd:
    """Observation statistics of P policies from their archive fields (P, ...) or (...)."""
    stats = RunningMeanStd.__new__(RunningMeanStd)
    stats.mean = torch.as_tensor(np.atleast_2d(fields["obs_mean"]), dtype=torch.float64)
    stats.var = torch.as_tensor(np.atleast_2d(fields["obs_var"]), dtype=torch.float64)
    stats.count = torch.as_tensor(np.atleast_1d(fields["obs_count"]), dtype=torch.float64)
    return stats


def fields_from_stats(stats: RunningMeanStd, lengths: np.ndarray) -> dict[str, np.ndarray]:
    """Archive fields (P, ...) of P policies: their statistics and episode lengths."""
    return {
        "obs_mean": stats.mean.cpu().numpy().copy(),  # pyribs keeps them on the host
        "obs_var": stats.var.cpu().numpy().copy(),
        "obs_count": stats.count.cpu().numpy().copy(),
        "length": np.asarray(lengths, dtype=np.float64),
    }
