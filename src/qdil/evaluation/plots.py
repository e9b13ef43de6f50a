"""Figures: archive heatmaps (pyribs' ``ribs.visualize``) and learning curves."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
from matplotlib.figure import Figure
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
