"""The report's figures: archive heatmaps, learning curves and return profiles.

Every archive of a task shares one colour scale; curves are the mean over a method's seeds
with a ±std band, on the iterations all of its seeds logged (``metrics.csv``); return
profiles (:mod:`qdil.evaluation.profiles`) likewise, on one return axis per task.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from ribs.archives import GridArchive

from qdil.evaluation.profiles import method_profile, profile_thresholds
from qdil.evaluation.runs import (
    Groups,
    RunResult,
)
from qdil.evaluation.stats import (
    align_curves,
)

CURVE_METRICS: tuple[tuple[str, str, float], ...] = (
    ("qd/qd_score", "QD-Score", 1.0),
    ("qd/coverage", "coverage (%)", 100.0),
    ("qd/obj_max", "best return", 1.0),
    ("qd/obj_mean", "average return", 1.0),
)
"""(metrics.csv column, axis label, scale) of the learning curves."""


HEATMAP_DPI = 100
"""Resolution of the heatmap PNGs (the report page places its clickable cells in pixels)."""


@dataclass(frozen=True)
class HeatmapGrid:
    """Where a heatmap PNG draws the archive's grid: pixel edges of its cells.

    Attributes:
        width: PNG width in pixels.
        height: PNG height in pixels.
        x_edges: (dims[0] + 1,) pixel columns of the first measure's cell boundaries.
        y_edges: (dims[1] + 1,) pixel rows of the second measure's cell boundaries (rows
            count down from the top, so they decrease); a 1-D archive's two rows span the
            strip it is drawn in.
    """

    width: int
    height: int
    x_edges: np.ndarray
    y_edges: np.ndarray

    def box(self, cell: Sequence[int]) -> tuple[float, float, float, float]:
        """``(x, y, w, h)`` of a cell in pixels, ``(x, y)`` its top left corner."""
        i, j = cell[0], cell[1] if len(cell) > 1 else 0
        left, right = self.x_edges[i], self.x_edges[i + 1]
        bottom, top = self.y_edges[j], self.y_edges[j + 1]
        return float(left), float(top), float(right - left), float(bottom - top)


def heatmap_grid(figure: Any, archive: GridArchive) -> HeatmapGrid:
    """The pixel grid of a heatmap that :func:`~qdil.evaluation.plots.archive_heatmap` drew.

    Call it after ``figure.savefig(..., dpi=HEATMAP_DPI)``, which lays the axes out.
    """
    ax = figure.axes[0]  # the heatmap; the colour bar is the second
    scale = HEATMAP_DPI / figure.dpi
    width, height = (np.round(figure.get_size_inches() * HEATMAP_DPI)).astype(int)
    x = ax.transData.transform(np.c_[archive.boundaries[0], np.zeros(archive.dims[0] + 1)])
    y_bounds = archive.boundaries[1] if archive.measure_dim > 1 else np.array(ax.get_ylim())
    y = ax.transData.transform(np.c_[np.full(len(y_bounds), archive.lower_bounds[0]), y_bounds])
    return HeatmapGrid(int(width), int(height), x[:, 0] * scale, height - y[:, 1] * scale)


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "run"


def colour_range(archives: Iterable[GridArchive | None]) -> tuple[float | None, float | None]:
    """Smallest and largest objective over archives: one colour scale for a task."""
    objectives = [a.data("objective") for a in archives if a is not None and len(a)]
    if not objectives:
        return None, None
    values = np.concatenate(objectives)
    return float(values.min()), float(values.max())


def plot_heatmaps(
    groups: Groups, out: Path, grids: dict[Path, HeatmapGrid] | None = None
) -> dict[Path, str]:
    """Save a heatmap of every run's final archive under ``out/heatmaps``.

    Args:
        groups: the report's runs.
        out: the report folder.
        grids: filled with run directory -> where its PNG draws the grid, if given.

    Returns:
        Run directory -> PNG path relative to ``out``.
    """
    import matplotlib.pyplot as plt

    from qdil.evaluation.plots import archive_heatmap

    (out / "heatmaps").mkdir(parents=True, exist_ok=True)
    made: dict[Path, str] = {}
    for task, runs_by_method in groups.items():
        vmin, vmax = colour_range(r.archive for runs in runs_by_method.values() for r in runs)
        for method, runs in runs_by_method.items():
            for run in runs:
                name = f"heatmaps/{_slug(task)}__{_slug(method)}__{_slug(run.path.name)}"
                while f"{name}.png" in made.values():
                    name += "_"
                title = f"{method} · seed {run.seed} · {task}\n{run.source}"
                try:
                    figure = archive_heatmap(run.archive, title=title, vmin=vmin, vmax=vmax)
                except ValueError as error:  # pyribs draws 1-D and 2-D grids only
                    run.notes.append(f"no heatmap: {error}")
                    continue
                figure.savefig(out / f"{name}.png", dpi=HEATMAP_DPI)
                if grids is not None:
                    grids[run.path] = heatmap_grid(figure, run.archive)
                plt.close(figure)
                made[run.path] = f"{name}.png"
    return made


def method_curves(
    runs: Sequence[RunResult], key: str, scale: float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and std over a method's seeds of one ``metrics.csv`` column.

    Returns:
        ``(iterations, mean, std)``, shapes ``(T,)``, on the iterations all seeds have.
    """
    curves = [(r.curves[key][0], scale * r.curves[key][1]) for r in runs if key in r.curves]
    if len(curves) < len(runs):
        return np.zeros(0), np.zeros(0), np.zeros(0)
    return align_curves(curves)


def plot_curves(groups: Groups, out: Path) -> dict[str, list[tuple[str, str]]]:
    """Save learning curves (one PNG per task and metric) under ``out/curves``.

    Returns:
        Task -> ``(metric label, PNG path relative to out)`` pairs.
    """
    import matplotlib.pyplot as plt

    from qdil.evaluation.plots import learning_curves

    (out / "curves").mkdir(parents=True, exist_ok=True)
    made: dict[str, list[tuple[str, str]]] = {}
    for task, runs_by_method in groups.items():
        for key, label, scale in CURVE_METRICS:
            lines = {}
            for method, runs in runs_by_method.items():
                steps, mean, std = method_curves(runs, key, scale)
                if len(steps):
                    lines[method] = (steps, mean, std, len(runs))
            figure = learning_curves(lines, title=f"{task}: {label}", ylabel=label)
            name = f"curves/{_slug(task)}__{_slug(key.split('/')[-1])}.png"
            figure.savefig(out / name, dpi=100)
            plt.close(figure)
            made.setdefault(task, []).append((label, name))
    return made


def plot_profiles(groups: Groups, out: Path) -> dict[str, str]:
    """Save the return profile of every task's final archives (one PNG per task).

    Returns:
        Task -> PNG path relative to ``out`` (tasks whose archives are all empty have none).
    """
    import matplotlib.pyplot as plt

    from qdil.evaluation.plots import learning_curves

    (out / "profiles").mkdir(parents=True, exist_ok=True)
    made: dict[str, str] = {}
    for task, runs_by_method in groups.items():
        thresholds = profile_thresholds(runs_by_method)
        if not len(thresholds):
            continue
        lines = {
            method: (thresholds, *method_profile(runs, thresholds), len(runs))
            for method, runs in runs_by_method.items()
        }
        figure = learning_curves(
            lines,
            title=f"{task}: return profile of the final archives",
            ylabel="cells whose elite returns ≥ x (%)",
            xlabel="return x",
        )
        name = f"profiles/{_slug(task)}.png"
        figure.savefig(out / name, dpi=100)
        plt.close(figure)
        made[task] = name
    return made
