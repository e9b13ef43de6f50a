"""Run records: the few files of a finished run that a report needs, kept with the report.

:func:`write_record` copies a run's recipe, metrics and provenance and writes its final
numbers and its archive without policies; a record is a run directory that
:func:`qdil.evaluation.runs.load_run` reads (:func:`is_record`, :func:`read_record`), so a
report outlives the machine that trained its runs: docs/guides/reproduce-paper-results.md.
"""

from __future__ import annotations

import csv
import io
import json
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from ribs.archives import GridArchive

from qdil.evaluation.rescore import EVAL_JSON
from qdil.files import CONFIG_NAME, open_table, write_gzipped
from qdil.provenance import PROVENANCE_JSON

RECORD_JSON = "record.json"
ARCHIVE_CSV = "archive.csv"  # kept as archive.csv.gz
METRICS_CSV = "metrics.csv"  # kept as metrics.csv.gz
RECORD_FORMAT = 1
COPIED = (CONFIG_NAME, EVAL_JSON, PROVENANCE_JSON)


@dataclass
class Record:
    """What a report keeps of one run besides its config and curves.

    Attributes:
        iteration: the iteration of the final archive.
        source: where the final metrics came from (corrected or training archive).
        metrics: final metrics, keys of :func:`qdil.qd.archives.qd_metrics`.
        archive: the final archive (only objectives and measures are kept).
        notes: remarks the report made on the run.
        method: the run's method label in the report (``--label`` or the recipe's), so that
            a report remade from records groups the runs as the original did.
        deployable: final metrics of the deployable archive (empty where none).
        deployable_source: where they came from.
    """

    iteration: int | None
    source: str
    metrics: dict[str, float]
    archive: GridArchive
    notes: list[str] = field(default_factory=list)
    method: str | None = None
    deployable: dict[str, float] = field(default_factory=dict)
    deployable_source: str = ""


class RecordError(ValueError):
    """A record's files are missing or unreadable."""


def is_record(path: Path) -> bool:
    """Whether a run directory is a record (``record.json`` and no checkpoint)."""
    return (path / RECORD_JSON).is_file() and not (path / "checkpoints").is_dir()


def write_record(run_dir: Path, record: Record, dest: Path, made_by: dict) -> Path:
    """Write the record of a run into ``dest`` (replaced if it exists).

    Args:
        run_dir: the run directory (or a record kept by another report, copied as it is).
        record: the run's final numbers and archive, as the report read them.
        dest: the record's folder.
        made_by: the report's provenance, taken before it wrote anything (a report
            rewriting its tracked folder would otherwise call its own tree dirty).

    Returns:
        ``dest``.
    """
    if dest.resolve() == run_dir.resolve():
        return dest  # the run is this record already
    tmp = dest.with_name(dest.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    if is_record(run_dir):  # a record kept by another report: copied, with this report's label
        shutil.copytree(run_dir, tmp)
        summary = json.loads((tmp / RECORD_JSON).read_text())
        if record.method is not None:
            summary["method"] = record.method
        (tmp / RECORD_JSON).write_text(json.dumps(summary, indent=1) + "\n")
        return _swap(tmp, dest)
    tmp.mkdir(parents=True)
    for name in COPIED:
        if (run_dir / name).is_file():
            shutil.copy2(run_dir / name, tmp / name)
    if (run_dir / METRICS_CSV).is_file():
        write_gzipped(tmp / f"{METRICS_CSV}.gz", (run_dir / METRICS_CSV).read_bytes())
    archive = record.archive
    summary = {
        "format": RECORD_FORMAT,
        "origin": str(run_dir),
        "iteration": record.iteration,
        "source": record.source,
        "metrics": record.metrics,
        "deployable": {"source": record.deployable_source, "metrics": record.deployable},
        "notes": [note for note in record.notes if not note.startswith("seed ")],
        "method": record.method,
        "dims": [int(d) for d in archive.dims],
        "ranges": [
            [float(lo), float(hi)]
            for lo, hi in zip(archive.lower_bounds, archive.upper_bounds, strict=True)
        ],
        "provenance": _provenance(run_dir, made_by),
    }
    (tmp / RECORD_JSON).write_text(json.dumps(summary, indent=1) + "\n")
    data = archive.data(["index", "objective", "measures"])
    table = io.StringIO(newline="")
    writer = csv.writer(table)
    k = len(archive.dims)
    writer.writerow(["index", "objective", *[f"measures_{j}" for j in range(k)]])
    for index, objective, measures in zip(
        data["index"], data["objective"], data["measures"], strict=True
    ):
        writer.writerow([int(index), repr(float(objective)), *map(repr, map(float, measures))])
    write_gzipped(tmp / f"{ARCHIVE_CSV}.gz", table.getvalue().encode())
    return _swap(tmp, dest)


def _provenance(run_dir: Path, made_by: dict) -> dict:
    """Who made the run's numbers: training starts, re-scoring, and this report."""
    found: dict = {"training": None, "evaluation": None, "report": made_by}
    if (run_dir / PROVENANCE_JSON).is_file():
        found["training"] = json.loads((run_dir / PROVENANCE_JSON).read_text())
    if (run_dir / EVAL_JSON).is_file():
        summary = json.loads((run_dir / EVAL_JSON).read_text())
        keys = ("reset_seed", "episodes_per_elite", "iteration", "provenance")
        found["evaluation"] = {key: summary.get(key) for key in keys}
    return found


def _swap(tmp: Path, dest: Path) -> Path:
    # one rename puts the record in place, so a killed report never leaves half of one
    if dest.exists():
        shutil.rmtree(dest)
    tmp.rename(dest)
    return dest


def read_record(path: Path) -> Record:
    """Read the record kept in ``path``.

    Args:
        path: a folder for which :func:`is_record` holds.

    Returns:
        The record; its source says which run it was kept from.

    Raises:
        RecordError: a file is missing or unreadable.
    """
    try:
        summary = json.loads((path / RECORD_JSON).read_text())
        metrics = {key: float(value) for key, value in summary["metrics"].items()}
        dims, ranges = summary["dims"], summary["ranges"]
        with open_table(path / ARCHIVE_CSV) as file:  # gzipped, or plain in older records
            rows = list(csv.reader(file))[1:]
        values = np.array(rows, dtype=np.float64).reshape(len(rows), 2 + len(dims))
    except (OSError, ValueError, KeyError, TypeError) as error:
        message = f"record unreadable ({error!r}); write it again with qdil report"
        raise RecordError(message) from error
    archive = GridArchive(solution_dim=1, dims=dims, ranges=[tuple(r) for r in ranges])
    if len(values):
        archive.add(np.zeros((len(values), 1)), values[:, 1], values[:, 2:])
    origin = f"from the record of {summary.get('origin', '?')}"
    source = f"{summary.get('source', '?')}; {origin}"
    notes = summary.get("notes", [])
    deployable = summary.get("deployable") or {}  # records of before the deployable archive
    return Record(
        summary.get("iteration"),
        source,
        metrics,
        archive,
        notes,
        summary.get("method"),
        {key: float(value) for key, value in (deployable.get("metrics") or {}).items()},
        f"{deployable['source']}; {origin}" if deployable.get("metrics") else "",
    )
