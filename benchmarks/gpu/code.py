"""Which code a GPU check ran: the machine's copy of the tree has no git to ask."""

from __future__ import annotations

import hashlib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def code_version() -> str:
    """A hash of the code and recipes the check runs (the GPU machine's copy has no git).

    The sha256 of every Python file under ``src/qdil`` and ``benchmarks`` and every GPU
    recipe, by path and content: two checks share it when they ran the same code.
    """
    digest = hashlib.sha256()
    files = [*(ROOT / "src" / "qdil").rglob("*.py"), *(ROOT / "benchmarks").rglob("*.py")]
    files += (ROOT / "recipes" / "gpu").glob("*.yaml")
    for path in sorted(files):
        digest.update(str(path.relative_to(ROOT)).encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:16]
