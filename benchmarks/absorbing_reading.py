"""The absorbing-state protocol's reading, applied to its records (docs/evidence-protocol.md).

``python benchmarks/absorbing_reading.py [RECORDS]`` reads each run's ``eval.json`` under
RECORDS (default docs/reports/absorbing-evidence/runs) whose configuration turns absorbing
states on, and prints one row per run: its target (Humanoid: the true-keyed archive's best
corrected elite at least 3,000; Walker2d: its corrected QD-Score at least 9.6e5), the figure,
hit or miss, the deployable archive beside it, and the scoring the protocol requires (its
task's episodes per elite, the QD-Score's standard error under 1 %).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path

import yaml

RECORDS = Path(__file__).resolve().parents[1] / "docs/reports/absorbing-evidence/runs"
# episodes per elite per task: 5, and 10 on Humanoid once the 1 % rule fired on its first run
EPISODES = {"Humanoid-v5": 10, "Walker2d-v5": 5}
SE_RULE = 0.01
# task -> (metric of eval.json's "metrics", target, label); fixed by the protocol page
TARGETS = {
    "Humanoid-v5": ("obj_max", 3_000.0, "best corrected elite"),
    "Walker2d-v5": ("qd_score", 9.6e5, "corrected QD-Score"),
}


@dataclass(frozen=True)
class Reading:
    """One run read against its target."""

    run: str
    task: str
    seed: int
    metric: str
    target: float
    value: float
    deployable: float
    episodes: int
    se_pct: float
    commit: str

    @property
    def hit(self) -> bool:
        return self.value >= self.target

    @property
    def scored_as_required(self) -> bool:
        return self.episodes == EPISODES[self.task] and self.se_pct < 100 * SE_RULE


def absorbing(config: dict) -> str | None:
    """The run's ``reward.init_args.absorbing`` in its parsed ``config.yaml``."""
    return ((config.get("reward") or {}).get("init_args") or {}).get("absorbing")


def read(run_dir: Path, config: dict) -> Reading:
    """Reads one run's ``eval.json`` (``config``: its parsed ``config.yaml``) against its target.

    Raises:
        ValueError: the run has no ``eval.json`` (not re-scored) or its task has no target.
    """
    path = run_dir / "eval.json"
    if not path.is_file():
        per_task = ", ".join(f"{n} on {t}" for t, n in EPISODES.items())
        raise ValueError(
            f"{run_dir}: no eval.json; re-score it: qdil eval {run_dir} --episodes N ({per_task})"
        )
    record = json.loads(path.read_text())
    if record["task"] not in TARGETS:
        raise ValueError(f"{path}: task {record['task']!r} has no target ({sorted(TARGETS)})")
    metric, target, _ = TARGETS[record["task"]]
    metrics = record["metrics"]
    return Reading(
        run=run_dir.name,
        task=record["task"],
        seed=int(config["seed"]),
        metric=metric,
        target=target,
        value=float(metrics[metric]),
        deployable=float(record["deployable"]["metrics"][metric]),
        episodes=int(record["episodes_per_elite"]),
        se_pct=100 * float(record["qd_score_se"]) / abs(float(metrics["qd_score"])),
        commit=record["provenance"]["commit"][:7],
    )


def readings(records: Path = RECORDS) -> list[Reading]:
    """Every run under ``records`` that turns absorbing states on, in name order."""
    runs = sorted(p for p in records.iterdir() if (p / "config.yaml").is_file())
    configs = {run: yaml.safe_load((run / "config.yaml").read_text()) for run in runs}
    return [read(run, config) for run, config in configs.items() if absorbing(config)]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "records",
        nargs="?",
        type=Path,
        default=RECORDS,
        help="folder of run records, one per sub-folder (default: %(default)s)",
    )
    records = parser.parse_args(argv).records
    if not records.is_dir():
        parser.error(f"RECORDS {records} is not a folder of run records")
    print(
        "| run | seed | target | true-keyed | reading | deployable | episodes | SE of QD-Score "
        "| commit |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for r in readings(records):
        label = TARGETS[r.task][2]
        fmt = (lambda v: f"{v:.2e}") if r.metric == "qd_score" else (lambda v: f"{v:,.0f}")
        scoring = "" if r.scored_as_required else " (not scored as the protocol requires)"
        print(
            f"| {r.run} | {r.seed} | {label} ≥ {fmt(r.target)} | {fmt(r.value)} | "
            f"{'hit' if r.hit else 'miss'}{scoring} | {fmt(r.deployable)} | {r.episodes} | "
            f"{r.se_pct:.2f} % | `{r.commit}` |"
        )


if __name__ == "__main__":
    main()
