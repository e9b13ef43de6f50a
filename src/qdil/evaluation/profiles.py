"""Return profiles of final archives: the share of the grid whose elites return at least x.

:func:`archive_profile` gives one archive's profile, :func:`method_profile` its mean over
seeds; the report plots them and tabulates them at :data:`PROFILE_LEVELS` of the task's best
return. Why a profile: docs/guides/reproduce-paper-results.md (``profiles/*.png``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from ribs.archives import GridArchive

from qdil.evaluation.runs import Groups, RunResult
from qdil.evaluation.stats import format_mean_std, summarize

PROFILE_LEVELS: tuple[float, ...] = (0.25, 0.5, 0.75)
"""Fractions of a task's best return at which the profile table reads the profiles."""

PROFILE_POINTS = 200
"""Returns x at which a plotted profile is evaluated, evenly over the task's range."""


def archive_profile(archive: GridArchive, thresholds: np.ndarray) -> np.ndarray:
    """Percentage of the archive's cells whose elite returns at least each threshold.

    Args:
        archive: a final archive (its objectives are the returns).
        thresholds: (T,) returns x.

    Returns:
        (T,) percentages of ``archive.cells``, non-increasing in x when thresholds increase.
    """
    thresholds = np.asarray(thresholds, dtype=np.float64)
    objectives = np.sort(archive.data("objective")) if len(archive) else np.zeros(0)
    at_least = len(objectives) - np.searchsorted(objectives, thresholds, side="left")
    return 100.0 * at_least / archive.cells


def method_profile(
    runs: Sequence[RunResult], thresholds: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and sample std (``ddof=1``; zeros for one seed) of the runs' profiles.

    Args:
        runs: one method's runs of one task, each with its final archive.
        thresholds: (T,) returns x.

    Returns:
        ``(mean, std)``, each (T,), in percent of the grid's cells.
    """
    stacked = np.stack([archive_profile(run.archive, thresholds) for run in runs])
    std = stacked.std(axis=0, ddof=1) if len(runs) > 1 else np.zeros(stacked.shape[1])
    return stacked.mean(axis=0), std


def task_returns(runs_by_method: Mapping[str, Sequence[RunResult]]) -> np.ndarray:
    """Every elite return of a task's final archives, shape (E,) (empty if none)."""
    values = [
        run.archive.data("objective")
        for runs in runs_by_method.values()
        for run in runs
        if run.archive is not None and len(run.archive)
    ]
    return np.concatenate(values) if values else np.zeros(0)


def profile_thresholds(runs_by_method: Mapping[str, Sequence[RunResult]]) -> np.ndarray:
    """(PROFILE_POINTS,) returns from the task's lowest to its best elite (empty if none)."""
    returns = task_returns(runs_by_method)
    if not len(returns):
        return np.zeros(0)
    return np.linspace(returns.min(), returns.max(), PROFILE_POINTS)


def profile_levels(runs_by_method: Mapping[str, Sequence[RunResult]]) -> list[float]:
    """The table's returns: :data:`PROFILE_LEVELS` of the best, to two significant digits."""
    returns = task_returns(runs_by_method)
    if not len(returns):
        return []
    return [float(f"{level * returns.max():.2g}") for level in PROFILE_LEVELS]


def profile_table(groups: Groups, task: str) -> tuple[list[str], list[list[str]]]:
    """Rows = methods, columns = % of cells whose elite returns at least each level.

    Returns:
        Header and rows of text cells, ``mean ± std`` over seeds (``(n=1)`` for one).
    """
    runs_by_method = groups[task]
    levels = profile_levels(runs_by_method)
    header = ["Method", "n"] + [f"cells ≥ {level:,.0f} (%)" for level in levels]
    rows = []
    for method, runs in runs_by_method.items():
        shares = np.stack([archive_profile(run.archive, np.array(levels)) for run in runs])
        cells = [format_mean_std(summarize(shares[:, j]), "fixed") for j in range(len(levels))]
        rows.append([method, str(len(runs)), *cells])
    return header, rows


def profile_records(groups: Groups) -> list[dict[str, Any]]:
    """One CSV record per task × method × level: the share's mean, std and n over seeds."""
    records = []
    for task, runs_by_method in groups.items():
        for level in profile_levels(runs_by_method):
            for method, runs in runs_by_method.items():
                shares = [float(archive_profile(r.archive, np.array([level]))[0]) for r in runs]
                summary = summarize(shares)
                records.append(
                    {
                        "task": task,
                        "method": method,
                        "return_at_least": level,
                        "cells_pct_mean": summary.mean,
                        "cells_pct_std": summary.std,
                        "n": summary.n,
                    }
                )
    return records
