"""A run's logged metrics without its timings, to compare two runs row for row."""

from __future__ import annotations

import csv
from pathlib import Path


def rows(run_dir: Path) -> list[dict[str, str]]:
    """``metrics.csv`` of ``run_dir``, each row without the ``perf/`` timings (env steps kept)."""
    with open(run_dir / "metrics.csv", newline="") as file:
        return [
            {k: v for k, v in row.items() if not k.startswith("perf/") or k == "perf/env_steps"}
            for row in csv.DictReader(file)
        ]
