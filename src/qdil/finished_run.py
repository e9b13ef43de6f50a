"""A run folder read-only: its recipe, metrics and archives, and its elites as policies.

:func:`open_run` reads what ``qdil fit`` (or :class:`qdil.Experiment`) wrote and changes
none of it. Re-scoring, reports and policy files are the functions the ``eval``, ``report``
and ``export`` commands call; their files go where you say, never into the run.
"""

from __future__ import annotations

import csv
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from qdil.files import CONFIG_NAME, open_table, table_path
from qdil.recipe_load import RecipeError

if TYPE_CHECKING:
    import numpy as np

    from qdil.envs.vector import LocomotionVectorEnv
    from qdil.evaluation.report import Report
    from qdil.export import ExportedPolicy, GaitPolicy

ARCHIVES = ("true", "deployable")


def open_run(run_dir: str | Path) -> FinishedRun:
    """The run in ``run_dir``, read-only.

    Raises:
        RecipeError: if ``run_dir`` holds no run (no ``config.yaml``).
    """
    return FinishedRun(run_dir)


class FinishedRun:
    """A run folder, finished or stopped at a checkpoint, read-only.

    Args:
        run_dir: a folder ``qdil fit`` made.

    Attributes:
        run_dir: the folder.
        config: its recipe as it ran (``config.yaml``, every default filled in).
    """

    def __init__(self, run_dir: str | Path) -> None:
        self.run_dir = Path(run_dir)
        path = self.run_dir / CONFIG_NAME
        if not path.is_file():
            raise RecipeError(
                f"{self.run_dir} is not a qdil run directory (no {CONFIG_NAME}); give a "
                "directory made by `qdil fit RECIPE.yaml`"
            )
        self.config: dict[str, Any] = yaml.safe_load(path.read_text())
        self._archives: dict[str, tuple[Any, int]] = {}

    def __repr__(self) -> str:
        return f"FinishedRun({str(self.run_dir)!r})"

    @property
    def task(self) -> str:
        """The gymnasium task id."""
        return self.config["env"]["task"]

    def metrics(self) -> list[dict[str, float]]:
        """Every logged iteration's metrics (``metrics.csv``), oldest first; empty cells NaN."""
        path = table_path(self.run_dir / "metrics.csv")  # a record keeps it gzipped
        if not path.is_file():
            return []
        with open_table(path) as file:
            return [
                {key: float(value) if value not in ("", None) else float("nan")
                 for key, value in row.items()}
                for row in csv.DictReader(file)
            ]  # fmt: skip

    def archive(self, which: str = "true") -> Any:
        """A policy archive of the last checkpoint (a pyribs ``GridArchive``).

        Args:
            which: ``true`` (keyed by the true return: the paper's) or ``deployable``
                (keyed by the run's own objective, what a user without the true reward
                keeps).

        Raises:
            ValueError: for another ``which``.
            CheckpointError: without a readable checkpoint.
        """
        return self._loaded(which)[0]

    @property
    def iteration(self) -> int:
        """The iteration of the last checkpoint."""
        return self._loaded("true")[1]

    def _loaded(self, which: str) -> tuple[Any, int]:
        if which not in ARCHIVES:
            raise ValueError(f"which must be one of {', '.join(ARCHIVES)}, got {which!r}")
        if which not in self._archives:
            from qdil.qd.checkpoint import load_archive

            self._archives[which] = load_archive(self.run_dir, which)
        return self._archives[which]

    @cached_property
    def _settings(self) -> Any:
        from qdil.evaluation.rescore import ReplaySettings

        return ReplaySettings.of_run(self.run_dir)

    @cached_property
    def _action_space(self) -> Any:
        """The task's action space (bounds), read once: each policy maps into it."""
        return self.make_env(1).single_action_space

    def make_env(self, num_envs: int = 1, num_threads: int | None = None) -> LocomotionVectorEnv:
        """The task as the run plays it (horizon, options, integrator), equal to gymnasium's.

        A vector of ``num_envs`` simulations that do not reset by themselves: ``reset``
        returns (num_envs, obs_dim) observations, ``step`` takes (num_envs, A) actions.
        """
        return self._settings.make_env(num_envs, num_threads)

    def policy(self, cell: list[int] | None = None, which: str = "true") -> GaitPolicy:
        """An elite as a deterministic policy: observations in, the task's actions out.

        Args:
            cell: the grid cell, one index per measure (``None``: the best elite).
            which: the archive (see :meth:`archive`).

        Raises:
            ValueError: for an empty archive, a cell outside the grid or an empty cell.
        """
        from qdil.evaluation.elites import select_rows

        archive = self.archive(which)
        elites = archive.data()
        (row,) = select_rows(archive, elites, cell, None)
        return self._policy(elites, int(row))

    def policies(self, top: int, which: str = "true") -> list[GaitPolicy]:
        """``top`` elites spread over the measures from the best, as policies."""
        from qdil.evaluation.elites import select_rows

        archive = self.archive(which)
        elites = archive.data()
        return [self._policy(elites, int(row)) for row in select_rows(archive, elites, None, top)]

    def _policy(self, elites: dict[str, np.ndarray], row: int) -> GaitPolicy:
        from qdil.export import GaitPolicy

        space = self._action_space
        return GaitPolicy(
            elites["solution"][row],
            elites["obs_mean"][row],
            elites["obs_var"][row],
            self._settings.actor_hidden,
            self._settings.obs_clip,
            space.low,
            space.high,
        )

    def rescore(
        self,
        which: str = "true",
        episodes: int = 5,
        seed: int = 0,
        num_threads: int | None = None,
        progress: bool = False,
    ) -> tuple[Any, dict[str, Any]]:
        """Every elite of an archive played for deterministic episodes on the true reward.

        What ``qdil eval`` measures, returned rather than written into the run.

        Returns:
            The corrected archive and its summary
            (:func:`qdil.evaluation.rescore.rescore`).
        """
        from qdil.evaluation.rescore import rescore

        loaded = self._loaded(which)
        return rescore(self.run_dir, which, episodes, 64, seed, num_threads, progress, loaded)

    def export(self, out: str | Path, fmt: str = "onnx", **options: Any) -> list[ExportedPolicy]:
        """Elites as policy files in ``out``, as ``qdil export`` writes them.

        ``options``: those of :func:`qdil.export.export_policies` (``which``, ``cell``,
        ``top``, ``episodes``, ``seed``).
        """
        from qdil.export import export_policies

        return export_policies(self.run_dir, out, fmt, **options)

    def report(self, out: str | Path, **options: Any) -> Report:
        """This run's report in ``out``, as ``qdil report`` writes it.

        ``options``: those of :func:`qdil.evaluation.report.write_report` (``labels``,
        ``records``, ``videos``, ...).
        """
        from qdil.evaluation.report import write_report

        return write_report([self.run_dir], out, **options)
