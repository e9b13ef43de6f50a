"""The archives of a QD-IL run and their metrics (decisions D1 and D10).

:class:`RunArchives` holds a run's three archives over the foot-contact measures:
``main`` (CMA-MAE's search archive, keyed on the learned return: a grid, or a CVT archive),
``true`` (a grid keyed on the true return: the paper's) and ``deployable`` (a grid keyed on
the run's own objective). :func:`qd_metrics` scores one
archive. Why three: docs/concepts/loop.md; the metrics: docs/concepts/metrics.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from ribs.archives import ArchiveBase, CVTArchive, GridArchive

from qdil.timing import ARCHIVE_WORK, timed

QD_OFFSETS: dict[str, float] = {
    "Walker2d-v5": 1.413,
    "HalfCheetah-v5": 9.231,
    "Humanoid-v5": 0.0,
    "Hopper-v5": 0.9,
    "Ant-v5": 3.24,
}
"""Per-step reward offsets of the offset QD-Score: QDax's values that PPGA reports with.

PPGA's offset QD-Score adds ``offset × episode length`` to every elite's return so that
negative returns count as small positive contributions. QDax tuned these for Brax's
rewards; for gymnasium's v5 rewards they are kept for comparability with PPGA's tables
(see docs/concepts/metrics.md for how far gymnasium's worst per-step rewards fall below
them).
"""


def elite_fields(obs_dim: int) -> dict[str, tuple[tuple[int, ...], type]]:
    """Pyribs ``extra_fields`` of policy archives: observation statistics and length."""
    return {
        "obs_mean": ((obs_dim,), np.float64),
        "obs_var": ((obs_dim,), np.float64),
        "obs_count": ((), np.float64),
        "length": ((), np.float64),
    }


def deployable_fields(obs_dim: int) -> dict[str, tuple[tuple[int, ...], type]]:
    """:func:`elite_fields` and the elite's true return (the deployable archive's)."""
    return elite_fields(obs_dim) | {"true_return": ((), np.float64)}


def true_keyed(archive: GridArchive) -> GridArchive:
    """The deployable archive's elites with their true returns as objectives.

    The cells, policies and statistics are the deployable archive's own: these are the
    policies a user gets, scored the way the paper scores its true archive.
    """
    keyed = make_grid(
        solution_dim=archive.solution_dim,
        cells=list(archive.dims),
        extra_fields=elite_fields(archive.data(["obs_mean"])["obs_mean"].shape[1]),
    )
    data = archive.data()
    if len(data["index"]):
        fields = {key: data[key] for key in ("obs_mean", "obs_var", "obs_count", "length")}
        keyed.add(data["solution"], data["true_return"], data["measures"], **fields)
    return keyed


def make_grid(
    *,
    solution_dim: int,
    cells: Sequence[int],
    extra_fields: dict,
    learning_rate: float | None = None,
    threshold_min: float = -np.inf,
    seed: int | None = None,
) -> GridArchive:
    """A GridArchive over [0, 1]^k with float32 policies (they are tens of thousands long)."""
    kwargs = {}
    if learning_rate is not None:
        kwargs = {"learning_rate": learning_rate, "threshold_min": threshold_min}
    return GridArchive(
        solution_dim=solution_dim,
        dims=list(cells),
        ranges=[(0.0, 1.0)] * len(cells),
        solution_dtype=np.float32,
        extra_fields=extra_fields,
        seed=seed,
        **kwargs,
    )


CENTROIDS = "centroids.npy"
"""A run's file of its CVT search archive's centroids (``qd.archive.type: cvt``)."""


def make_cvt(
    *,
    solution_dim: int,
    centroids: np.ndarray,
    extra_fields: dict,
    learning_rate: float,
    threshold_min: float,
    seed: int | None = None,
) -> CVTArchive:
    """A CVTArchive over [0, 1]^k with the given (cells, k) centroids, float32 policies."""
    return CVTArchive(
        solution_dim=solution_dim,
        centroids=centroids,
        ranges=[(0.0, 1.0)] * centroids.shape[1],
        learning_rate=learning_rate,
        threshold_min=threshold_min,
        solution_dtype=np.float32,
        extra_fields=extra_fields,
        seed=seed,
    )


@dataclass
class RunArchives:
    """The three archives of a run (see the module docstring)."""

    main: ArchiveBase  # the search archive: a grid, or a CVT archive
    true: GridArchive
    deployable: GridArchive

    @timed(ARCHIVE_WORK)
    def add(
        self,
        solutions: np.ndarray,
        objective: np.ndarray,
        true_objective: np.ndarray,
        measures: np.ndarray,
        fields: dict[str, np.ndarray],
    ) -> None:
        """Insert solutions into the passive archives (the scheduler fills ``main``).

        Args:
            solutions: (P, D) policies.
            objective: (P,) the run's own objective (the ``main`` archive's).
            true_objective: (P,) true returns.
            measures: (P, k) episode measures.
            fields: :func:`elite_fields` values, each (P, ...).
        """
        self.true.add(solutions, true_objective, measures, **fields)
        self.deployable.add(solutions, objective, measures, true_return=true_objective, **fields)


def qd_metrics(archive: ArchiveBase, offset: float = 0.0) -> dict[str, float]:
    """QD metrics of an archive, from pyribs' ``archive.stats``.

    Args:
        archive: a GridArchive with a ``length`` field.
        offset: per-step offset of the offset QD-Score.

    Returns:
        ``qd_score`` (Σ objectives: the QDIL/WQDIL papers' QD-Score), ``qd_score_offset``
        (Σ objective + offset·length: PPGA's), ``coverage`` (fraction of cells),
        ``obj_max`` (best), ``obj_mean`` (average), ``num_elites``.
    """
    stats = archive.stats
    empty = stats.num_elites == 0
    offset_score = 0.0
    if not empty:
        data = archive.data(["objective", "length"])
        offset_score = float(np.sum(data["objective"] + offset * data["length"]))
    return {
        "qd_score": float(stats.qd_score),
        "qd_score_offset": offset_score,
        "coverage": float(stats.coverage),
        "obj_max": float("nan") if empty else float(stats.obj_max),
        "obj_mean": float("nan") if empty else float(stats.obj_mean),
        "num_elites": float(stats.num_elites),
    }
