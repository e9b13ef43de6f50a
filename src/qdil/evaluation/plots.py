"""Figures: archive heatmaps (pyribs' ``ribs.visualize``) and learning curves."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from ribs.archives import GridArchive


def archive_heatmap(
    archive: GridArchive,
    title: str = "",
    vmin: float | None = None,
    vmax: float | None = None,
    ax: plt.Axes | None = None,
) -> Figure:
    """Heatmap of the best return per cell over two foot-contact measures.

    Args:
        archive: a 2-D (or 1-D) GridArchive.
        title: axes title.
        vmin: lower end of the colour scale (share it across archives of one task).
        vmax: upper end of the colour scale.
        ax: axes to draw on; a new figure if ``None``.
    """
    import ribs.visualize

    if ax is None:
        figure, ax = plt.subplots(figsize=(5, 4.2))
    else:
        figure = ax.figure
    ribs.visualize.grid_archive_heatmap(archive, ax=ax, vmin=vmin, vmax=vmax, cmap="magma")
    ax.set_xlabel("foot 1 contact fraction")
    if archive.measure_dim > 1:
        ax.set_ylabel("foot 2 contact fraction")
    ax.set_title(title, fontsize=9)
    figure.tight_layout()
    return figure


def learning_curves(
    curves: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, int]],
    title: str = "",
    ylabel: str = "",
    xlabel: str = "iteration",
) -> Figure:
    """Mean over seeds with a shaded ±std band, one line per method.

    Args:
        curves: method -> ``(x, mean, std, n_seeds)``; the arrays have shape
            ``(T_method,)`` (see :func:`qdil.evaluation.stats.align_curves`).
        title: axes title.
        ylabel: y-axis label.
        xlabel: x-axis label; the axis has integer ticks when it is ``"iteration"``.
    """
    figure, ax = plt.subplots(figsize=(5.5, 3.8))
    for method, (steps, mean, std, n) in curves.items():
        (line,) = ax.plot(steps, mean, label=f"{method} (n={n})", linewidth=1.5)
        if n > 1:
            ax.fill_between(steps, mean - std, mean + std, color=line.get_color(), alpha=0.2)
    ax.set_xlabel(xlabel)
    if xlabel == "iteration":
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    if curves:
        ax.legend(fontsize=7)
    figure.tight_layout()
    return figure
