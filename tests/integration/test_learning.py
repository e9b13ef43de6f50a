"""Learning checks on the laptop recipes (minutes each): ``pytest -m slow``.

They check that the algorithms learn, not only that they run; CI does not select them.
The thresholds sit well below what the recipes reached at the same iteration in the
records of docs/reports/walker-comparison (Walker2d PPGA-trueReward, seeds 0-2 at iteration
15: best 2,870-3,326, coverage 20.6-22.0 %).
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import pytest

from qdil.cli import main

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow


def last_row(tmp_path: Path, name: str) -> dict[str, float]:
    with open(tmp_path / "runs" / name / "metrics.csv", newline="") as file:
        row = list(csv.DictReader(file))[-1]
    return {key: float(value) for key, value in row.items() if value}


@pytest.fixture(autouse=True)
def every_core(monkeypatch, tmp_path):
    monkeypatch.delenv("QDIL_NUM_THREADS", raising=False)  # learning runs use every core
    monkeypatch.chdir(tmp_path)


def test_ppga_on_the_true_reward_learns_to_walk(tmp_path: Path) -> None:
    main(
        [
            "fit",
            str(ROOT / "recipes" / "walker_ppga.yaml"),
            "--qd.iterations",
            "15",
            "--name",
            "ppga",
            "--logging.wandb",
            "disabled",
            "--logging.progress",
            "false",
        ]
    )
    metrics = last_row(tmp_path, "ppga")
    assert metrics["qd/obj_max"] > 1000
    assert metrics["qd/coverage"] > 0.03


def test_wqdil_imitates_the_shipped_walker_demonstrations(tmp_path: Path) -> None:
    main(
        [
            "fit",
            str(ROOT / "recipes" / "walker_mcwae.yaml"),
            "--qd.iterations",
            "15",
            "--name",
            "wqdil",
            "--logging.wandb",
            "disabled",
            "--logging.progress",
            "false",
        ]
    )
    metrics = last_row(tmp_path, "wqdil")
    assert metrics["qd/obj_max"] > 500  # true return, never seen by the learner
    assert metrics["qd/coverage"] > 0.03
    assert os.path.exists(tmp_path / "runs" / "wqdil" / "checkpoints" / "last.pt")
