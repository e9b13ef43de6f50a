"""Metrics of a run: ``metrics.csv`` always, W&B through Lightning's logger, a progress bar.

:class:`Tracker` writes every QD iteration's metrics to :class:`MetricsCSV` and, if enabled,
to W&B; :class:`Progress` is the bar. Every metric name: docs/concepts/metrics.md; W&B:
docs/guides/wandb.md.
"""

from __future__ import annotations

import csv
import math
import os
import secrets
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from tqdm.auto import tqdm

from qdil.config import finished
from qdil.files import atomic_write

if TYPE_CHECKING:
    from qdil.config import LoggingConfig, QDConfig
    from qdil.qd.archives import RunArchives


class _Counters(Protocol):
    @property
    def iteration(self) -> int:
        """The current QD iteration."""

    @property
    def env_steps(self) -> int:
        """Env steps simulated so far."""


class TrackedRun(Protocol):
    """What the tracker reads of a run; :class:`qdil.qd.state.Run` has it.

    A protocol rather than ``Run`` itself: the run holds its tracker, so naming ``Run`` here,
    even for annotations, would make the two modules import each other.
    """

    @property
    def name(self) -> str:
        """The run's name (the title of heatmaps)."""

    @property
    def qd(self) -> QDConfig:
        """Its QD settings (the last iteration, :func:`finished`, gets a heatmap)."""

    @property
    def archives(self) -> RunArchives:
        """Its archives (the true-return one is drawn and tabled)."""

    @property
    def state(self) -> _Counters:
        """Its counters (``iteration``: the step of the final table)."""


WANDB_ID = Path("wandb") / "qdil-run-id"
"""Where a run directory keeps its W&B run id (relative to the run directory)."""


def wandb_run_id(run_dir: Path, name: str) -> str:
    """The W&B run id of the run in ``run_dir``: made at its first start, read on every resume.

    A new id is the run's name and a random suffix, so that two runs of the same name (the
    same recipe and seed on two machines, or a run directory deleted and started again)
    never continue each other's W&B run; every start of one run uses the id kept in
    :data:`WANDB_ID`, so a resume continues the same W&B run.

    Args:
        run_dir: the run directory.
        name: the run's name.
    """
    path = run_dir / WANDB_ID
    if path.is_file():
        return path.read_text().strip()
    if path.parent.is_dir():  # started before ids were kept: its W&B id was its name
        run_id = name.replace("/", "-")
    else:
        run_id = f"{name.replace('/', '-')}-{secrets.token_hex(4)}"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(run_id + "\n")
    return run_id


def check_wandb_login(mode: str) -> str | None:
    """Why ``logging.wandb: online`` cannot log from here, or ``None`` if it can.

    Checked before a run does any work: wandb itself asks for the key only when the run
    starts, after the envs, the reward model and its pretraining are built. Any key counts
    that wandb would use (``WANDB_API_KEY``, ``wandb login``'s ``.netrc`` entry, a settings
    file); it is verified with the server, which an online run needs anyway.

    Args:
        mode: ``logging.wandb`` (only ``online`` is checked).
    """
    if mode != "online":
        return None
    import wandb

    # the recipe's mode, not $WANDB_MODE, decides: wandb.init(mode="online") overrides it
    wandb.setup(settings=wandb.Settings(mode="online"))
    try:
        if wandb.login(verify=True, prompt=False):
            return None
        problem = "no W&B API key found"
    except Exception as error:  # a rejected key, an unreachable server
        problem = str(error).splitlines()[0] if str(error) else type(error).__name__
    return (
        f"--logging.wandb online needs a W&B login ({problem}): run `wandb login` or set "
        "WANDB_API_KEY, or log offline (--logging.wandb offline) and `wandb sync` later"
    )


class MetricsCSV:
    """An append-only CSV of metric rows that widens its header when new keys appear.

    Args:
        path: the CSV file.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.keys: list[str] = []
        if path.exists():
            with open(path, newline="") as file:
                self.keys = list(csv.DictReader(file).fieldnames or [])

    def rows(self) -> list[dict[str, str]]:
        """Every row written so far."""
        if not self.path.exists():
            return []
        with open(self.path, newline="") as file:
            return list(csv.DictReader(file))

    def _rewrite(self, rows: list[dict[str, Any]]) -> None:
        def write(file: Any) -> None:
            text = _TextFile(file)
            writer = csv.DictWriter(text, fieldnames=self.keys)
            writer.writeheader()
            writer.writerows(rows)

        atomic_write(self.path, write)

    def truncate(self, last_iteration: int) -> None:
        """Drop rows after ``last_iteration`` (logged after the checkpoint a run resumes from)."""
        rows = [row for row in self.rows() if int(float(row["iteration"])) <= last_iteration]
        self._rewrite(rows)

    def write(self, row: dict[str, Any]) -> None:
        """Append one row (rewriting the file if it brings new keys)."""
        new = [key for key in row if key not in self.keys]
        if new:
            old = self.rows()
            self.keys += new
            self._rewrite(old)
        with open(self.path, "a", newline="") as file:
            csv.DictWriter(file, fieldnames=self.keys).writerow(row)
            file.flush()
            os.fsync(file.fileno())


class _TextFile:
    """Adapts a binary file to csv's text writer."""

    def __init__(self, file: Any) -> None:
        self.file = file

    def write(self, text: str) -> int:
        return self.file.write(text.encode())


class Progress:
    """A progress bar: iteration, QD-Score, coverage, best return, env-steps/s."""

    def __init__(self, start: int, total: int, enabled: bool) -> None:
        self.bar = tqdm(
            total=total, initial=start, disable=not enabled, unit="itr", dynamic_ncols=True
        )

    def update(self, metrics: dict[str, float]) -> None:
        """Advance one iteration and show its headline metrics."""
        self.bar.set_postfix(
            qd=f"{metrics['qd/qd_score']:.3g}",
            cov=f"{100 * metrics['qd/coverage']:.1f}%",
            best=f"{metrics['qd/obj_max']:.0f}" if not math.isnan(metrics["qd/obj_max"]) else "-",
            sps=f"{metrics['perf/sps']:.0f}",
            refresh=False,
        )
        self.bar.update(1)

    def close(self) -> None:
        """Close the bar."""
        self.bar.close()


class Tracker:
    """Writes every iteration's metrics to ``metrics.csv`` and, if enabled, to W&B.

    Args:
        run_dir: the run directory.
        logging: the recipe's logging section.
        name: the run name (W&B run name; the id is :func:`wandb_run_id`).
        config: the resolved recipe, logged to W&B.
    """

    def __init__(self, run_dir: Path, logging: LoggingConfig, name: str, config: dict) -> None:
        self.run_dir = run_dir
        self.logging = logging
        self.csv = MetricsCSV(run_dir / "metrics.csv")
        self.wandb = None
        if logging.wandb != "disabled":
            import wandb
            from lightning.pytorch.loggers import WandbLogger

            # the run is started here rather than by the logger, whose wandb.init passes
            # ``anonymous``, a setting wandb 0.31 warns about on every run
            # "allow": the first start creates the W&B run, every resume continues it (offline,
            # each start writes its own offline-run-* folder of that id; `wandb sync` of them
            # all uploads them into the one run, in order)
            experiment = wandb.init(
                name=name,
                id=wandb_run_id(run_dir, name),
                project=logging.wandb_project,
                group=logging.wandb_group,
                dir=str(run_dir),
                mode=logging.wandb,
                resume="allow",
                config=config,
            )
            self.wandb = WandbLogger(experiment=experiment)

    def progress(self, start: int, total: int) -> Progress:
        """A progress bar from ``start`` to ``total`` iterations."""
        return Progress(start, total, self.logging.progress)

    def log(self, metrics: dict[str, float], iteration: int, run: TrackedRun) -> None:
        """Record one iteration's metrics (and the archive heatmap every K iterations)."""
        self.csv.write({"iteration": iteration, **metrics})
        if self.wandb is not None:
            self.wandb.log_metrics(metrics, step=iteration)
            every = self.logging.heatmap_every
            if every and (
                iteration % every == 0 or finished(run.qd, iteration, run.state.env_steps)
            ):
                from qdil.evaluation.plots import archive_heatmap

                figure = archive_heatmap(
                    run.archives.true, title=f"{run.name} · iteration {iteration}"
                )
                self.wandb.log_image("archive/heatmap", [figure], step=iteration)

    def finish(self, run: TrackedRun) -> None:
        """Log the final archive as a table and close W&B."""
        if self.wandb is None:
            return
        data = run.archives.true.data(["objective", "measures", "index"], return_type="pandas")
        self.wandb.log_table("archive/elites", dataframe=data, step=run.state.iteration)
        self.wandb.finalize("success")
        import wandb

        wandb.finish()

    @property
    def wants_videos(self) -> bool:
        """Whether the run ends with videos of its elites in W&B (``logging.videos``)."""
        return self.wandb is not None and self.logging.videos > 0

    def log_videos(self, videos: list[Any], iteration: int) -> None:
        """Log rendered elites as ``archive/videos``, captioned with cell, return and measures.

        Args:
            videos: :class:`qdil.evaluation.video.Video` records of the files to log.
            iteration: the QD iteration they show.
        """
        if self.wandb is None or not videos:
            return
        captions = [
            f"cell {list(v.cell)}: true return {v.episode_return:.0f}, measures "
            f"{[round(float(m), 2) for m in v.measures]}"
            for v in videos
        ]
        self.wandb.log_video(
            "archive/videos",
            [str(v.path) for v in videos],
            step=iteration,
            caption=captions,
            format=[v.path.suffix[1:] for v in videos],
        )
