"""Choosing elites of an archive: the best, one cell's, or K spread over the measure space.

Shared by ``qdil render`` and ``qdil export``, so that ``--best``, ``--cell`` and ``--top``
pick the same elites in both.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from qdil.demos.generate import farthest_point_sampling


def select_rows(
    archive: Any, elites: dict[str, np.ndarray], cell: list[int] | None, top: int | None
) -> np.ndarray:
    """Archive rows: the best elite, one cell's, or ``top`` spread over the measures.

    ``top`` elites are chosen by farthest-point sampling in measure space from the best one
    (as demonstrations are, :mod:`qdil.demos.generate`).

    Raises:
        ValueError: for an empty archive, a cell outside the grid or an empty cell.
    """
    if not len(elites["objective"]):
        raise ValueError("the archive holds no elites yet; train longer (qdil fit --resume)")
    best = int(np.argmax(elites["objective"]))
    if top is not None:
        return farthest_point_sampling(elites["measures"], top, start=best)
    if cell is None:
        return np.array([best])
    dims = [int(d) for d in archive.dims]
    if len(cell) != len(dims) or not all(0 <= i < d for i, d in zip(cell, dims, strict=True)):
        ranges = ", ".join(f"0 to {d - 1}" for d in dims)
        raise ValueError(
            f"--cell {' '.join(map(str, cell))} is not a cell of the {'×'.join(map(str, dims))} "
            f"grid: give {len(dims)} indices, one per measure, in {ranges}"
        )
    rows = np.flatnonzero(elites["index"] == archive.grid_to_int_index([cell])[0])
    if not rows.size:
        order = np.argsort(-elites["objective"], kind="stable")[:8]
        cells = archive.int_to_grid_index(elites["index"][order])
        occupied = ", ".join(" ".join(map(str, c)) for c in cells)
        raise ValueError(
            f"cell {tuple(cell)} is empty; occupied cells, best first: {occupied}"
            f"{' ...' if len(elites['index']) > len(order) else ''} (or --best / --top K)"
        )
    return rows
