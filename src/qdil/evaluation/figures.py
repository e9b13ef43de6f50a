"""The report's figures: archive heatmaps, learning curves and return profiles.

Every archive of a task shares one colour scale; curves are the mean over a method's seeds
with a ±std band, on the iterations all of its seeds logged (``metrics.csv``); return
profiles (:mod:`qdil.evaluation.profiles`) likewise, on one return axis per task.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from pathlib import Path

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


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "run"


def colour_range(archives: Iterable[GridArchive | None]) -> tuple[float | None, float | None]:
    """Smallest and largest objective over archives: one colour scale for a task."""
    objectives = [a.data("objective") for a in archives if a is not None and len(a)]
    if not objectives:
        return None, None
    values = np.concatenate(objectives)
    return float(values.min()), float(values.max())


def plot_heatmaps(groups: Groups, out: Path) -> dict[Path, str]:
    """Save a heatmap of every run's final archive under ``out/heatmaps``.

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
                figure.savefig(out / f"{name}.png", dpi=100)
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
