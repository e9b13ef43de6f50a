"""Run directories as ``qdil report`` sees them: discovery, tasks, final archives.

:func:`collect_runs` finds and reads every run (:func:`load_run`); a run's final numbers come
from ``qdil eval``'s corrected archives when they were made from its checkpoint, else from
the checkpoint, and :attr:`RunResult.source` says which. Which runs are left out or
unfinished, and why: docs/guides/reproduce-paper-results.md.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import pickle
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from ribs.archives import GridArchive

from qdil.envs.integrators import task_label
from qdil.envs.tasks import changed_for_task
from qdil.evaluation.methods import DISPLAY_NAMES, method_label
from qdil.evaluation.records import RecordError, is_record, read_record
from qdil.evaluation.rescore import CORRECTED, EVAL_JSON
from qdil.files import CONFIG_NAME, open_table, table_path
from qdil.provenance import PROVENANCE_JSON, mixed_vendors_note
from qdil.qd.archives import QD_OFFSETS, qd_metrics, true_keyed
from qdil.qd.checkpoint import CheckpointError, load_archives
from qdil.upgrades import upgraded

METRICS_NAME = "metrics.csv"

TASK_ORDER = ("HalfCheetah-v5", "Walker2d-v5", "Humanoid-v5")
"""The paper's column order; other tasks follow, sorted."""


@dataclass
class RunResult:
    """One run directory as the report sees it.

    Attributes:
        path: the run directory.
        task: ``env.task`` of its config (``None`` if unreadable).
        integrator: ``env.integrator`` where it is not the task model's own, else ``None``;
            such a run is grouped under its own task, :attr:`task_label`.
        method: the method label (see :func:`method_label`).
        seed: the recipe's seed.
        target: ``qd.iterations`` of the recipe.
        last_logged: last iteration in ``metrics.csv``.
        iteration: iteration of the checkpoint the final archive comes from.
        source: where the final metrics come from (corrected archive or training archive).
        metrics: final metrics, keys of :func:`qdil.qd.archives.qd_metrics`.
        archive: a light copy of the final archive (objectives and measures only).
        curves: ``metrics.csv`` column -> ``(iterations, values)``, each of shape ``(T,)``.
        problems: why the run is left out (empty if it is included).
        notes: remarks on an included run (unfinished, stale ``eval.json``, ...).
        deployable: final metrics of the deployable archive (empty where the run has none).
        deployable_source: where they come from.
        config: the resolved recipe (``config.yaml``), which decides the runs pooled in a row.
        labelled: whether ``method`` was given (``--label``) or kept by a record, not the
            recipe's default.
    """

    path: Path
    task: str | None = None
    integrator: str | None = None
    method: str | None = None
    seed: int | None = None
    target: int | None = None
    last_logged: int | None = None
    iteration: int | None = None
    source: str = ""
    metrics: dict[str, float] = field(default_factory=dict)
    archive: GridArchive | None = None
    curves: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    deployable: dict[str, float] = field(default_factory=dict)
    deployable_source: str = ""
    config: dict[str, Any] = field(default_factory=dict)
    labelled: bool = False

    @property
    def task_label(self) -> str | None:
        """The task as the report groups and names it: ``Walker2d-v5 (euler)`` if changed."""
        return None if self.task is None else task_label(self.task, self.integrator)

    @property
    def included(self) -> bool:
        """Whether the run goes into tables and figures."""
        return not self.problems

    @property
    def unfinished(self) -> bool:
        """Whether the run stopped before ``qd.iterations`` and its ``qd.env_steps`` budget."""
        if self.target is None:
            return False
        reached = [i for i in (self.last_logged, self.iteration) if i is not None]
        return bool(reached) and min(reached) < self.target and not self._spent(min(reached))

    def _spent(self, iteration: int) -> bool:
        """Whether the run's env steps at ``iteration`` (logged) reached its budget."""
        budget = (self.config.get("qd") or {}).get("env_steps")
        steps, values = self.curves.get("perf/env_steps", ((), ()))
        return budget is not None and any(
            s == iteration and v >= budget for s, v in zip(steps, values, strict=True)
        )

    @property
    def status(self) -> str:
        """``included``, ``included, unfinished`` or ``left out``."""
        if not self.included:
            return "left out"
        return "included, unfinished" if self.unfinished else "included"


Groups = dict[str, dict[str, list[RunResult]]]
"""task -> method -> included runs."""


def find_runs(paths: Iterable[str | Path]) -> tuple[list[Path], list[RunResult]]:
    """Run directories under the given paths (each a run, or a folder of runs one level down).

    Args:
        paths: run directories or folders that contain run directories.

    Returns:
        The run directories (in order, without duplicates) and a left-out entry for every
        path that is neither.
    """
    runs: list[Path] = []
    missing: list[RunResult] = []
    for raw in paths:
        path = Path(raw)
        if (path / CONFIG_NAME).is_file():
            found = [path]
        elif path.is_dir():
            found = sorted(p for p in path.iterdir() if (p / CONFIG_NAME).is_file())
        else:
            found = []
        if not found:
            reason = f"no {CONFIG_NAME} in it or in its sub-directories"
            reason = reason if path.exists() else "it does not exist"
            missing.append(RunResult(path=path, problems=[f"not a run directory: {reason}"]))
        for run in found:
            if run.resolve() not in {r.resolve() for r in runs}:
                runs.append(run)
    return runs, missing


def read_curves(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Columns of ``metrics.csv`` against iteration; a repeated iteration keeps its last row.

    Args:
        path: the ``metrics.csv`` file (or a record's ``metrics.csv.gz``).

    Returns:
        Column -> ``(iterations, values)``, shapes ``(T,)``; missing cells are NaN.
    """
    with open_table(path) as file:
        rows = list(csv.DictReader(file))
    by_iteration = {int(float(row["iteration"])): row for row in rows if row.get("iteration")}
    steps = np.array(sorted(by_iteration), dtype=np.int64)
    curves = {}
    for key in rows[0].keys() if rows else []:
        if key == "iteration":
            continue
        values = [_float(by_iteration[int(s)].get(key)) for s in steps]
        curves[key] = (steps, np.array(values, dtype=np.float64))
    return curves


def _float(value: str | None) -> float:
    try:
        return float(value) if value not in (None, "") else math.nan
    except ValueError:
        return math.nan


def light_copy(archive: GridArchive) -> GridArchive:
    """The objectives and measures of an archive in a GridArchive without policies.

    Args:
        archive: a GridArchive (policies of tens of thousands of parameters per elite).

    Returns:
        An archive with the same grid and elites and ``solution_dim`` 1.
    """
    light = GridArchive(
        solution_dim=1,
        dims=list(archive.dims),
        ranges=list(zip(archive.lower_bounds, archive.upper_bounds, strict=True)),
    )
    data = archive.data(["objective", "measures"])
    if len(data["objective"]):
        light.add(np.zeros((len(data["objective"]), 1)), data["objective"], data["measures"])
    return light


def _final_archive(run: RunResult, label: str | None = None) -> None:
    """Fill ``run``'s final archive, metrics and source (corrected archive preferred).

    A record also gives the method label its report used, unless ``label`` overrides it.
    """
    if is_record(run.path):
        try:
            record = read_record(run.path)
        except RecordError as error:
            run.problems.append(str(error))
            return
        run.method = label or record.method or run.method
        run.labelled = bool(label or record.method)
        run.iteration, run.source, run.metrics = record.iteration, record.source, record.metrics
        run.archive = record.archive
        run.notes.extend(record.notes)
        run.deployable, run.deployable_source = record.deployable, record.deployable_source
        return
    try:
        archives, run.iteration = load_archives(run.path)  # one read of the checkpoint
    except CheckpointError as error:
        run.problems.append(f"no readable checkpoint ({error})")
        return
    archive = archives["true"]
    offset = QD_OFFSETS.get(run.task or "", 0.0)
    run.metrics = qd_metrics(archive, offset)
    run.source = f"training archive (checkpoint, iteration {run.iteration})"
    _training_deployable(run, archives["deployable"], offset)
    eval_path, corrected_path = run.path / EVAL_JSON, run.path / CORRECTED
    if not eval_path.exists():
        run.archive = light_copy(archive)
        return
    try:
        summary = json.loads(eval_path.read_text())
        metrics = {key: float(value) for key, value in summary["metrics"].items()}
    except (ValueError, KeyError, TypeError) as error:
        run.notes.append(f"{EVAL_JSON} unreadable ({error}); training archive used")
        run.archive = light_copy(archive)
        return
    if summary.get("iteration") != run.iteration:
        run.notes.append(
            f"{EVAL_JSON} is from iteration {summary.get('iteration')}, the checkpoint from "
            f"{run.iteration}; training archive used (run `qdil eval` again)"
        )
        run.archive = light_copy(archive)
        return
    run.metrics = metrics
    episodes = summary.get("episodes_per_elite", "?")
    run.source = f"corrected (qdil eval, {episodes} episodes/elite, iteration {run.iteration})"
    if summary.get("deployable"):
        run.deployable = {k: float(v) for k, v in summary["deployable"]["metrics"].items()}
        run.deployable_source = run.source
    if corrected_path.exists():
        with open(corrected_path, "rb") as file:
            archive = pickle.load(file)  # our own file, written by qdil eval
    else:
        run.notes.append(f"no {CORRECTED}: heatmap shows the training archive")
    run.archive = light_copy(archive)


def _training_deployable(run: RunResult, deployable: Any, offset: float) -> None:
    """The deployable archive's metrics by its elites' training true returns, if it has one."""
    if deployable is None:
        run.notes.append("no deployable archive (its checkpoint predates it)")
        return
    run.deployable = qd_metrics(true_keyed(deployable), offset)
    run.deployable_source = run.source


def _changed_integrator(task: str, env: Mapping[str, Any]) -> str | None:
    """``env.integrator`` where it is not the task model's own, else None."""
    asked = env.get("integrator")
    try:
        return changed_for_task(task, env.get("task_kwargs"), asked)
    except (ValueError, FileNotFoundError):  # a task not known here: as the run asked
        return str(asked)


def load_run(path: Path, label: str | None = None) -> RunResult:
    """Read one run directory: config, learning curves, final archive and metrics.

    Args:
        path: the run directory.
        label: method label overriding the one a record kept and :func:`method_label`.

    Returns:
        The run; ``problems`` says why it is left out, ``notes`` what to know about it.
    """
    run = RunResult(path=path)
    try:
        # read as today's, so that runs from before a class or key moved pool with later ones
        config = upgraded(yaml.safe_load((path / CONFIG_NAME).read_text()) or {})
        run.task = config["env"]["task"]
    except (OSError, yaml.YAMLError, KeyError, TypeError) as error:
        run.problems.append(f"{CONFIG_NAME} unreadable or without env.task ({error!r})")
        return run
    run.integrator = _changed_integrator(run.task, config["env"])
    run.method, run.labelled, run.config = label or method_label(config), bool(label), config
    run.seed = config.get("seed")
    run.target = (config.get("qd") or {}).get("iterations")
    metrics_path = table_path(path / METRICS_NAME)  # a record keeps it gzipped
    if metrics_path.exists():
        run.curves = read_curves(metrics_path)
    if not run.curves:
        run.problems.append(
            f"no {METRICS_NAME}" if not metrics_path.exists() else f"{METRICS_NAME} has no rows"
        )
    else:
        steps = next(iter(run.curves.values()))[0]
        run.last_logged = int(steps[-1]) if len(steps) else None
    _final_archive(run, label)
    if (path / PROVENANCE_JSON).is_file():
        with contextlib.suppress(ValueError, TypeError, AttributeError):
            note = mixed_vendors_note(json.loads((path / PROVENANCE_JSON).read_text()))
            if note is not None and note not in run.notes:  # a record keeps its note
                run.notes.append(note)
    if run.included and run.unfinished:
        run.notes.insert(
            0,
            f"unfinished: {run.last_logged} iterations logged, checkpoint at "
            f"{run.iteration}, recipe asks for {run.target}",
        )
    return run


def group_runs(runs: Iterable[RunResult]) -> Groups:
    """Included runs by task (paper order) and method (true reward first, then by name)."""
    groups: Groups = {}
    for run in runs:
        if run.included:
            groups.setdefault(run.task_label, {}).setdefault(run.method, []).append(run)

    def order(label: str) -> tuple[int, str]:  # a changed integrator beside its task
        task = label.split(" (")[0]
        return (TASK_ORDER.index(task) if task in TASK_ORDER else 99, label)

    tasks = sorted(groups, key=order)
    first = DISPLAY_NAMES["true_reward"]
    return {
        task: {
            method: sorted(groups[task][method], key=lambda r: (r.seed is None, r.seed, r.path))
            for method in sorted(groups[task], key=lambda m: (not m.startswith(first), m.lower()))
        }
        for task in tasks
    }


def collect_runs(
    paths: Iterable[str | Path], labels: Mapping[str | Path, str] | None = None
) -> list[RunResult]:
    """Find and read every run under ``paths``; left-out runs are kept, with their reasons.

    Args:
        paths: run directories, or folders whose direct sub-directories are runs.
        labels: run directory -> method label, overriding :func:`method_label`.

    Returns:
        The runs in the order found, then the paths that are not runs.
    """
    overrides = {Path(p).resolve(): label for p, label in (labels or {}).items()}
    run_dirs, missing = find_runs(paths)
    runs = [load_run(p, overrides.get(p.resolve())) for p in run_dirs] + missing
    unused = sorted(set(overrides) - {p.resolve() for p in run_dirs})
    runs += [RunResult(path=p, problems=["given with --label but not a run found"]) for p in unused]
    return runs
