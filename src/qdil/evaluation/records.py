"""Run records: the few kilobytes of a finished run that a report needs, kept beside it.

A run directory holds checkpoints of every policy (megabytes per elite archive) and lives on
the machine that trained it. A report's numbers should outlive that machine: ``qdil report``
copies, for every run it includes, a **record** into ``<out>/runs/<run name>/``:

- ``config.yaml`` and ``metrics.csv``, copied (the recipe that reproduces the run and its
  learning curves),
- ``eval.json``, copied when the numbers come from ``qdil eval``,
- ``record.json``: the iteration, the source of the final metrics, the metrics themselves and
  the notes the report made,
- ``archive.csv``: the final archive without policies, one row per elite (cell index,
  objective, measures).

A record is itself a run directory as :func:`qdil.evaluation.runs.load_run` reads it: a later
``qdil report docs/reports/x/runs runs/new-seed --out docs/reports/x`` rebuilds the same
tables from the records and adds the new run, with no checkpoint in sight.
"""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from ribs.archives import GridArchive

from qdil.evaluation.rescore import EVAL_JSON

if TYPE_CHECKING:
    from qdil.evaluation.runs import RunResult

RECORD_JSON = "record.json"
ARCHIVE_CSV = "archive.csv"
RECORD_FORMAT = 1
COPIED = ("config.yaml", "metrics.csv", EVAL_JSON)


def is_record(path: Path) -> bool:
    """Whether a run directory is a record (``record.json`` and no checkpoint)."""
    return (path / RECORD_JSON).is_file() and not (path / "checkpoints").is_dir()


def write_record(run: RunResult, dest: Path) -> Path:
    """Write the record of an included run into ``dest`` (replaced if it exists).

    Args:
        run: an included run, as :func:`qdil.evaluation.runs.load_run` read it.
        dest: the record's folder.

    Returns:
        ``dest``.

    Raises:
        ValueError: the run is left out of the report (it has no final archive).
    """
    if not run.included or run.archive is None:
        raise ValueError(f"{run.path} is left out of the report; it has no record to keep")
    if dest.resolve() == run.path.resolve():
        return dest  # the run is this record already
    tmp = dest.with_name(dest.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    if is_record(run.path):  # a record kept by another report: copied as it is
        shutil.copytree(run.path, tmp)
        return _swap(tmp, dest)
    tmp.mkdir(parents=True)
    for name in COPIED:
        if (run.path / name).is_file():
            shutil.copy2(run.path / name, tmp / name)
    summary = {
        "format": RECORD_FORMAT,
        "origin": str(run.path),
        "iteration": run.iteration,
        "source": run.source,
        "metrics": run.metrics,
        "notes": [note for note in run.notes if not note.startswith("seed ")],
        "dims": [int(d) for d in run.archive.dims],
        "ranges": [
            [float(lo), float(hi)]
            for lo, hi in zip(run.archive.lower_bounds, run.archive.upper_bounds, strict=True)
        ],
    }
    (tmp / RECORD_JSON).write_text(json.dumps(summary, indent=1) + "\n")
    data = run.archive.data(["index", "objective", "measures"])
    with open(tmp / ARCHIVE_CSV, "w", newline="") as file:
        writer = csv.writer(file)
        k = data["measures"].shape[1] if len(data["objective"]) else len(run.archive.dims)
        writer.writerow(["index", "objective", *[f"measures_{j}" for j in range(k)]])
        for index, objective, measures in zip(
            data["index"], data["objective"], data["measures"], strict=True
        ):
            writer.writerow([int(index), repr(float(objective)), *map(repr, map(float, measures))])
    return _swap(tmp, dest)


def _swap(tmp: Path, dest: Path) -> Path:
    # one rename puts the record in place, so a killed report never leaves half of one
    if dest.exists():
        shutil.rmtree(dest)
    tmp.rename(dest)
    return dest


def read_record(run: RunResult) -> None:
    """Fill ``run``'s iteration, final metrics, source and archive from its record.

    Args:
        run: a run whose directory :func:`is_record`; problems are added to it when the
            record cannot be read.
    """
    try:
        summary = json.loads((run.path / RECORD_JSON).read_text())
        run.iteration = summary["iteration"]
        run.metrics = {key: float(value) for key, value in summary["metrics"].items()}
        dims, ranges = summary["dims"], summary["ranges"]
        with open(run.path / ARCHIVE_CSV, newline="") as file:
            rows = list(csv.reader(file))[1:]
    except (OSError, ValueError, KeyError, TypeError) as error:
        run.problems.append(f"record unreadable ({error!r}); write it again with qdil report")
        return
    archive = GridArchive(solution_dim=1, dims=dims, ranges=[tuple(r) for r in ranges])
    if rows:
        values = np.array(rows, dtype=np.float64)
        archive.add(np.zeros((len(values), 1)), values[:, 1], values[:, 2:])
    run.archive = archive
    run.source = f"{summary.get('source', '?')}; from the record of {summary.get('origin', '?')}"
    run.notes.extend(summary.get("notes", []))
