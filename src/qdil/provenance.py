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


def _cpuinfo(field: str) -> str | None:
    try:
        with open("/proc/cpuinfo") as file:
            return next(line.split(":", 1)[1].strip() for line in file if line.startswith(field))
    except (OSError, StopIteration):
        return None


def _cpu() -> str:
    return _cpuinfo("model name") or platform.processor() or platform.machine()


def cpu_vendor(entry: dict[str, Any] | None = None) -> str:
    """The CPU's vendor (``GenuineIntel``, ``AuthenticAMD``, ...), here or of a start's entry.

    Entries written before ``cpu_vendor`` was recorded get it from their CPU's name.
    """
    if entry is None:
        return _cpuinfo("vendor_id") or platform.processor() or platform.machine()
    if entry.get("cpu_vendor"):
        return entry["cpu_vendor"]
    name = entry.get("cpu") or ""
    return "AuthenticAMD" if "AMD" in name else "GenuineIntel" if "Intel" in name else name


def vendors(starts: list[dict[str, Any]]) -> list[str]:
    """The CPU vendors of a run's starts (``provenance.json``), in order of first use."""
    return list(dict.fromkeys(cpu_vendor(start) for start in starts))


def mixed_vendors_note(starts: list[dict[str, Any]]) -> str | None:
    """What to say of a run whose starts ran on CPUs of more than one vendor (else ``None``)."""
    found = vendors(starts)
    if len(found) < 2:
        return None
    return (
        f"trained on CPUs of {len(found)} vendors ({', '.join(found)}): its numbers are not "
        "reproducible bit for bit on one machine (docs/concepts/reproducibility.md)"
    )


def provenance() -> dict[str, Any]:
    """What made the results being written now.

    Returns:
        ``commit`` and ``dirty`` (:func:`git_state`), ``versions`` of qdil, torch, mujoco,
        pyribs, numpy, gymnasium and Lightning, ``numerics`` (MKL's mode with its branch,
        torch's CPU kernels), ``cpu`` and ``cpu_vendor``, ``python`` and the UTC time
        ``created``.
    """
    from qdil import numerics

    commit, dirty = git_state()
    return {
        "commit": commit,
        "dirty": dirty,
        "versions": {package: _version(package) for package in PACKAGES},
        "numerics": numerics.worker_env(),
        "cpu": _cpu(),
        "cpu_vendor": cpu_vendor(),
        "python": platform.python_version(),
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
    }


def record_start(run_dir: Path, iteration: int) -> str | None:
    """Add this start of a run to its ``provenance.json``: a list, one entry per start.

    A run continued on a CPU of another vendor than its earlier starts gets a ``note`` in
    this start's entry saying that its numbers are no longer reproducible bit for bit on
    one machine (MKL takes other kernels on another vendor's CPU).

    Args:
        run_dir: the run directory.
        iteration: the iteration the run continues from (0: a start from scratch, which
            replaces the entries of an earlier attempt that never saved a checkpoint).

    Returns:
        That note, or ``None``.
    """
    path = run_dir / PROVENANCE_JSON
    starts = json.loads(path.read_text()) if iteration and path.is_file() else []
    entry = {"from_iteration": iteration, **provenance()}
    note = mixed_vendors_note([*starts, entry])
    if note is not None and cpu_vendor() not in vendors(starts):
        entry["note"] = f"resumed on a CPU of another vendor than before: {note}"
    starts.append(entry)
    atomic_write(path, lambda file: file.write((json.dumps(starts, indent=1) + "\n").encode()))
    return entry.get("note")
