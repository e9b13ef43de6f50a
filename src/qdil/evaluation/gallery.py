"""Videos for the report page: a few elites of every run, spread over its archive.

:func:`make_gallery` renders them as ``qdil render --top`` does, from the archive the
report's heatmap shows (:func:`policy_archive`); :attr:`Gallery.reason` and
:attr:`Gallery.notes` say why the page or a run has none. Which elites, the replay, the cost:
docs/guides/videos.md (section "The report page").
"""

from __future__ import annotations

import pickle
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from qdil.evaluation.records import is_record
from qdil.evaluation.rescore import CORRECTED
from qdil.evaluation.runs import Groups, RunResult
from qdil.evaluation.video import Video
from qdil.qd.checkpoint import CheckpointError, load_archive


@dataclass(frozen=True)
class VideoSettings:
    """How the report's videos are made.

    Attributes:
        count: elites per run (0: no videos).
        width: frame width in pixels (even: H.264).
        height: frame height in pixels (even).
        max_steps: episode horizon (``None``: the run's).
        fps: asked frame rate (see :func:`~qdil.evaluation.video.render_elites`).
        seed: reset seed of every episode.
    """

    count: int = 6
    width: int = 320
    height: int = 208
    max_steps: int | None = None
    fps: float = 30.0
    seed: int = 0


@dataclass
class Gallery:
    """The report's videos.

    Attributes:
        settings: how they were made.
        videos: run directory -> its videos, best elite first (paths inside the report).
        reason: why there are none at all (empty when some could be made).
        notes: run directory -> why that run has none.
        seconds: wall time of replaying, drawing and writing them.
    """

    settings: VideoSettings
    videos: dict[Path, list[Video]] = field(default_factory=dict)
    reason: str = ""
    notes: dict[Path, str] = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def count(self) -> int:
        """Videos made."""
        return sum(len(videos) for videos in self.videos.values())


def policy_archive(run: RunResult) -> Any:
    """The archive with policies behind a run's heatmap (corrected, else the checkpoint's).

    Raises:
        CheckpointError: the run is a record, or its checkpoint cannot be read.
    """
    if is_record(run.path):
        raise CheckpointError("a record kept by a report holds no policies to replay")
    corrected = run.path / CORRECTED
    if run.source.startswith("corrected") and corrected.exists():
        with open(corrected, "rb") as file:
            return pickle.load(file)  # our own file, written by qdil eval
    return load_archive(run.path, "true")[0]


def make_gallery(
    groups: Groups, out: Path, heatmaps: Mapping[Path, str], settings: VideoSettings
) -> Gallery:
    """Render ``settings.count`` elites of every run that has a heatmap.

    Args:
        groups: the report's included runs.
        out: the report folder; videos go into ``out/videos/<heatmap name>/``.
        heatmaps: run directory -> its heatmap PNG (relative to ``out``), which names the
            run's video folder.
        settings: how many videos per run, and how they are drawn.

    Returns:
        The videos, or why there are none.
    """
    from qdil.envs.gl import GLUnavailableError, use_gl_backend

    gallery = Gallery(settings)
    if settings.count <= 0:
        gallery.reason = "none asked for (qdil report --videos 0)"
        return gallery
    runs = [run for methods in groups.values() for rs in methods.values() for run in rs]
    runs = [run for run in runs if run.path in heatmaps]
    if not runs:
        return gallery
    try:
        use_gl_backend()
    except GLUnavailableError as error:
        gallery.reason = str(error)
        return gallery
    start = time.perf_counter()
    for run in runs:
        try:
            gallery.videos[run.path] = _render_run(run, out, heatmaps[run.path], settings)
        except CheckpointError as error:
            gallery.notes[run.path] = f"no videos: {error}"
    gallery.seconds = time.perf_counter() - start
    return gallery


def _render_run(run: RunResult, out: Path, heatmap: str, settings: VideoSettings) -> list[Video]:
    from qdil.evaluation.elites import select_rows
    from qdil.evaluation.video import render_rows

    archive = policy_archive(run)
    elites = archive.data()
    if not len(elites["objective"]):
        return []
    rows = select_rows(archive, elites, None, settings.count)
    cells = [tuple(int(i) for i in c) for c in archive.int_to_grid_index(elites["index"][rows])]
    folder = out / "videos" / Path(heatmap).stem
    paths = [folder / f"cell_{'_'.join(map(str, cell))}.mp4" for cell in cells]
    label = "corrected archive" if run.source.startswith("corrected") else "true archive"
    return render_rows(
        run.path,
        elites,
        rows,
        cells,
        paths,
        label,
        settings.width,
        settings.height,
        max_steps=settings.max_steps,
        seed=settings.seed,
        fps=settings.fps,
    )
