"""Crash-safe file writes, shared by checkpoints, metrics, demonstrations and evaluations.

:func:`atomic_write` writes to a temporary file in the target's folder, flushes it to disk and
renames it over the target, so a crash at any moment leaves either the old file or the new
one, never half of one. A write killed before its rename leaves its temporary file behind;
:func:`remove_stale_temporaries` deletes those of processes that no longer run. A report's
records keep their tables gzipped (:func:`write_gzipped`); :func:`open_table` reads either.

Only the standard library: this module sits below everything that writes files (the QD loop,
its checkpoints, the tracker, demonstration files), so it must import none of them.
"""

from __future__ import annotations

import gzip
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import IO

# a run directory's recipe, as `qdil fit` resolved it; the mark of a run directory
CONFIG_NAME = "config.yaml"

# atomic_write's temporary files: ".<name>.tmp-<pid>"
TEMPORARY = re.compile(r"^\..+\.tmp-(\d+)$")


def table_path(path: Path) -> Path:
    """``path``, or ``path`` + ``.gz`` where only the gzipped table is kept (a record's)."""
    gzipped = path.with_name(path.name + ".gz")
    return gzipped if not path.exists() and gzipped.exists() else path


def open_table(path: Path) -> IO[str]:
    """Open a CSV table as text for :mod:`csv`, plain or gzipped (:func:`table_path`)."""
    path = table_path(path)
    if path.suffix == ".gz":
        return gzip.open(path, "rt", newline="")
    return open(path, newline="")


def write_gzipped(path: Path, data: bytes) -> None:
    """Write ``data`` gzipped to ``path``, the same bytes for the same data (no timestamp)."""
    with open(path, "wb") as raw, gzip.GzipFile("", "wb", 9, raw, mtime=0) as file:
        file.write(data)


def atomic_write(path: Path, write: Callable[[IO[bytes]], object]) -> None:
    """Call ``write(file)`` on a temporary file, fsync it, then rename it over ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")  # see remove_stale_temporaries
    try:
        with open(tmp, "wb") as file:
            write(file)
            file.flush()
            os.fsync(file.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    directory = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(directory)
    finally:
        os.close(directory)


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists (it may be another user's)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except (OverflowError, ValueError):  # not a possible pid
        return False
    return True


def remove_stale_temporaries(*folders: Path) -> list[Path]:
    """Delete the temporary files that killed :func:`atomic_write` calls left in ``folders``.

    A write killed before its rename leaves ``.<name>.tmp-<pid>`` behind (for a checkpoint,
    as large as the checkpoint). Files of a process that still runs are kept: another qdil
    may be writing them right now.

    Args:
        *folders: the folders to clean (not recursively); missing ones are skipped.

    Returns:
        The files removed.
    """
    removed = []
    for folder in folders:
        if not folder.is_dir():
            continue
        for path in folder.iterdir():
            match = TEMPORARY.match(path.name)
            if match is None or not path.is_file():
                continue
            pid = int(match.group(1))
            if pid != os.getpid() and _alive(pid):
                continue
            path.unlink(missing_ok=True)
            removed.append(path)
    return removed
