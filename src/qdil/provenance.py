"""Provenance: which code, libraries, numerics and machine made a file of results.

Written into ``provenance.json`` of every run (one entry per start or resume), into
``eval.json`` and into report records, so that a number can be traced to its commit.
"""

from __future__ import annotations

import datetime
import importlib.metadata
import json
import platform
import subprocess
from pathlib import Path
from typing import Any

from qdil.files import atomic_write

PROVENANCE_JSON = "provenance.json"
PACKAGES = ("qdil", "torch", "mujoco", "ribs", "numpy", "gymnasium", "lightning")


def git_state(path: Path | None = None) -> tuple[str | None, bool | None]:
    """The commit of the git work tree that holds qdil's source, and whether it was dirty.

    Args:
        path: a file inside the package (default: its ``__init__.py``).

    Returns:
        ``(commit, dirty)``; ``(None, None)`` where qdil is not run from a git checkout
        (an installed wheel), or git is missing.
    """
    path = path or Path(__file__).with_name("__init__.py")

    def git(*args: str) -> str | None:
        try:
            done = subprocess.run(
                ["git", *args], cwd=path.parent, capture_output=True, text=True, timeout=10
            )
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout.strip() if done.returncode == 0 else None

    # only a tree that tracks this very file (not, say, a project holding a virtualenv)
    if git("ls-files", "--error-unmatch", path.name) is None:
        return None, None
    commit = git("rev-parse", "HEAD")
    status = git("status", "--porcelain", "--untracked-files=no")
    return commit, None if status is None else bool(status)


def _version(package: str) -> str | None:
    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return None


def _cpu() -> str:
    try:
        with open("/proc/cpuinfo") as file:
            return next(line.split(":", 1)[1].strip() for line in file if "model name" in line)
    except (OSError, StopIteration):
        return platform.processor() or platform.machine()


def provenance() -> dict[str, Any]:
    """What made the results being written now.

    Returns:
        ``commit`` and ``dirty`` (:func:`git_state`), ``versions`` of qdil, torch, mujoco,
        pyribs, numpy, gymnasium and Lightning, ``numerics`` (MKL's mode with its branch,
        torch's CPU kernels), ``cpu``, ``python`` and the UTC time ``created``.
    """
    from qdil import numerics

    commit, dirty = git_state()
    return {
        "commit": commit,
        "dirty": dirty,
        "versions": {package: _version(package) for package in PACKAGES},
        "numerics": numerics.worker_env(),
        "cpu": _cpu(),
        "python": platform.python_version(),
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }


def record_start(run_dir: Path, iteration: int) -> None:
    """Add this start of a run to its ``provenance.json``: a list, one entry per start.

    Args:
        run_dir: the run directory.
        iteration: the iteration the run continues from (0: a start from scratch, which
            replaces the entries of an earlier attempt that never saved a checkpoint).
    """
    path = run_dir / PROVENANCE_JSON
    starts = json.loads(path.read_text()) if iteration and path.is_file() else []
    starts.append({"from_iteration": iteration, **provenance()})
    atomic_write(path, lambda file: file.write((json.dumps(starts, indent=1) + "\n").encode()))
