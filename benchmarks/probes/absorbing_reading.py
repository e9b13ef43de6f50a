"""The absorbing-state protocol's reading, applied to its records (docs/evidence-protocol.md).

``python benchmarks/probes/absorbing_reading.py [RECORDS]`` reads each run's ``eval.json`` under
RECORDS (default docs/reports/absorbing-evidence/runs) whose configuration turns absorbing
states on, and prints one row per run: its target (Humanoid: the true-keyed archive's best
corrected elite at least 3,000; Walker2d: its corrected QD-Score at least 9.6e5), the figure,
hit or miss, the deployable archive beside it, and the scoring the protocol requires (its
task's episodes per elite, the QD-Score's standard error under 1 %).

``--training`` prints instead what each run's ``metrics.csv`` shows about why: the floor's
price of a step after a fall against a step alive (docs/concepts/survival.md), the
iterations whose 20 steps before a fall were paid more than the others, falls, the best
training elite and the critic's gap, the figures the protocol page's readings quote.
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from qdil.evaluation.runs import read_curves
from qdil.files import table_path

RECORDS = Path(__file__).resolve().parents[2] / "docs/reports/absorbing-evidence/runs"
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


def absorbing_runs(records: Path) -> dict[Path, dict]:
    """Run folder -> parsed ``config.yaml`` of every run under ``records`` with the option on."""
    runs = sorted(p for p in records.iterdir() if (p / "config.yaml").is_file())
    configs = {run: yaml.safe_load((run / "config.yaml").read_text()) for run in runs}
    return {run: config for run, config in configs.items() if absorbing(config)}


def readings(records: Path = RECORDS) -> list[Reading]:
    """Every run under ``records`` that turns absorbing states on, in name order."""
    return [read(run, config) for run, config in absorbing_runs(records).items()]


# iterations at which falls, the best training elite and the critic's gap are quoted
MARKS = (10, 20, 50, 70, 100, 120)


@dataclass(frozen=True)
class Training:
    """What one run's ``metrics.csv`` shows about staying up, from iteration ``since`` on.

    Prices are per step: ``floor`` is ``reward/absorbing`` (a step after a fall), ``alive``
    is ``survival/reward_alive`` (a step not among the last 20 before a fall), ``policy``
    is ``reward/train_per_step`` (every step of the training rollouts, bonus included).
    """

    run: str
    since: int
    last: int
    floor: tuple[float, float, float, float, float]  # median, 10th, 90th percentile, min, max
    alive: float  # median
    policy: float  # median
    gap: tuple[float, float]  # smallest and largest alive − floor of one iteration
    paid_more: tuple[int, ...]  # iterations whose steps before a fall paid more than alive
    falls: dict[int, float]  # falls per 1,000 steps at the MARKS the run reached
    best: dict[int, float]  # best training elite (qd/obj_max) at the MARKS
    best_from: int  # the iteration the run's final best was first reached
    critic_gap: dict[int, float]  # reward/critic_gap at the MARKS (empty for GAIL)


def training(run_dir: Path, since: int = 2) -> Training:
    """Reads ``run_dir``'s ``metrics.csv`` (one row per iteration) from iteration ``since``.

    Raises:
        ValueError: no ``metrics.csv``, or no row from ``since`` on.
    """
    path = table_path(run_dir / "metrics.csv")  # a record's is gzipped
    if not path.is_file():
        raise ValueError(f"{run_dir}: no metrics.csv; is it a run folder of qdil fit?")
    curves = read_curves(path)
    steps, best = curves["qd/obj_max"]
    if not (steps >= since).any():
        raise ValueError(f"{path}: no iteration from {since} on (last {steps.max()})")
    kept = steps >= since
    iterations = [int(i) for i in steps[kept]]

    def values(key: str) -> np.ndarray:  # (T,) over every iteration, NaN where not logged
        return curves[key][1] if key in curves else np.full(len(steps), np.nan)

    def column(key: str) -> np.ndarray:
        return values(key)[kept]

    def at_marks(key: str) -> dict[int, float]:
        marked = {m: float(values(key)[steps == m][0]) for m in MARKS if m in steps}
        return {m: v for m, v in marked.items() if not math.isnan(v)}

    floor, alive = column("reward/absorbing"), column("survival/reward_alive")
    before = column("survival/reward_before_fall")
    return Training(
        run=run_dir.name,
        since=since,
        last=iterations[-1],
        floor=tuple(float(v) for v in np.percentile(floor, [50, 10, 90, 0, 100])),
        alive=float(np.median(alive)),
        policy=float(np.median(column("reward/train_per_step"))),
        gap=(float((alive - floor).min()), float((alive - floor).max())),
        # NaN (nothing fell) compares False: such an iteration paid nothing more
        paid_more=tuple(i for i, b, a in zip(iterations, before, alive, strict=True) if b > a),
        falls=at_marks("survival/falls_per_1k_steps"),
        best=at_marks("qd/obj_max"),
        best_from=int(steps[np.argmax(best >= best.max())]),
        critic_gap=at_marks("reward/critic_gap"),
    )


def spans(iterations: list[int]) -> str:
    """``[1, 2, 3, 7]`` as ``1–3, 7``."""
    runs: list[list[int]] = []
    for i in iterations:
        if runs and i == runs[-1][-1] + 1:
            runs[-1].append(i)
        else:
            runs.append([i])
    return ", ".join(f"{r[0]}–{r[-1]}" if len(r) > 1 else f"{r[0]}" for r in runs)


def paid_more_cell(t: Training) -> str:
    """How many iterations paid more before a fall, naming the fewer side's iterations."""
    every = range(t.since, t.last + 1)
    more = set(t.paid_more)
    if len(more) * 2 > len(every):
        others = [i for i in every if i not in more]
        named = f" (not {spans(others)})" if others else ""
    else:
        named = f" ({spans(sorted(more))})" if more else ""
    return f"{len(more)} of {len(every)}{named}"


def print_training(records: Path, since: int) -> None:
    """One row per absorbing run: the figures of :class:`Training`."""
    print(f"training records from iteration {since} on; prices per step\n")
    print(
        "| run | floor median [p10, p90] (min to max) | alive median | policy median "
        "| alive − floor "
        "| paid more before a fall | falls per 1k | best training elite | critic gap |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for run in absorbing_runs(records):
        t = training(run, since)
        marks = lambda d, f: ", ".join(f"{m}: {f(v)}" for m, v in d.items())  # noqa: E731
        print(
            f"| {t.run} | {t.floor[0]:.2f} [{t.floor[1]:.2f}, {t.floor[2]:.2f}] "
            f"({t.floor[3]:.2f} to {t.floor[4]:.2f}) | {t.alive:.2f} | {t.policy:.2f} "
            f"| {t.gap[0]:.2f} to {t.gap[1]:.2f} | {paid_more_cell(t)} "
            f"| {marks(t.falls, lambda v: f'{v:.1f}' if v >= 1 else f'{v:.2f}')} "
            f"| {marks(t.best, lambda v: f'{v:,.0f}')} (final from {t.best_from}) "
            f"| {marks(t.critic_gap, lambda v: f'{v:.1f}') or '–'} |"
        )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "records",
        nargs="?",
        type=Path,
        default=RECORDS,
        help="folder of run records, one per sub-folder (default: %(default)s)",
    )
    parser.add_argument(
        "--training",
        action="store_true",
        help="print what each run's metrics.csv shows about staying up instead of the targets",
    )
    parser.add_argument(
        "--since",
        type=int,
        default=2,
        help="first iteration the training figures cover (default: %(default)s; the floor "
        "is priced from iteration 2 on)",
    )
    args = parser.parse_args(argv)
    records = args.records
    if not records.is_dir():
        parser.error(f"RECORDS {records} is not a folder of run records")
    if args.training:
        print_training(records, args.since)
        return
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
