"""The short runs' table of what a reward pays for falling (docs/evidence-protocol.md).

For each run folder: falls per 1,000 training steps, the reward per step alive and over the
last 20 steps before a fall (means over iterations 2 on) with the iterations whose steps
before a fall paid more, the best training elite (true return) so far, and the critic gap,
at the iterations asked for. Reads only ``metrics.csv``::

    python benchmarks/probes/falls_table.py RUN [RUN ...] --at 10 20
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

from qdil.files import open_table


def reading(run: Path, at: list[int]) -> str:
    """One table row of the run in ``run``."""
    with open_table(run / "metrics.csv") as file:  # a record's is gzipped
        rows = [row for row in csv.DictReader(file)]
    value = {int(r["iteration"]): r for r in rows}
    best, bests = -math.inf, {}
    for row in rows:
        best = max(best, float(row["qd/obj_max"]))
        bests[int(row["iteration"])] = best
    later = [r for r in rows if int(r["iteration"]) >= 2 and r["survival/reward_before_fall"]]
    alive = [float(r["survival/reward_alive"]) for r in later]
    fall = [float(r["survival/reward_before_fall"]) for r in later]
    fall_pairs = [(a, f) for a, f in zip(alive, fall, strict=True) if not math.isnan(f)]
    more = sum(f > a for a, f in fall_pairs)

    def at_each(key: str, digits: int) -> str:
        return " / ".join(
            f"{float(value[i][key]):.{digits}f}" if i in value and value[i].get(key) else "–"
            for i in at
        )

    mean_alive = sum(alive) / len(alive) if alive else math.nan
    mean_fall = sum(f for _, f in fall_pairs) / len(fall_pairs) if fall_pairs else math.nan
    best_at = " / ".join(f"{bests[i]:,.0f}" if i in bests else "–" for i in at)
    return (
        f"| {run.name} | {at_each('survival/falls_per_1k_steps', 1)} | {mean_alive:.2f} / "
        f"{mean_fall:.2f} | {more} of {len(fall_pairs)} | {best_at} | "
        f"{at_each('reward/critic_gap', 1)} |"
    )


def main() -> None:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run folders (with metrics.csv)")
    parser.add_argument("--at", nargs="+", type=int, default=[10, 20], help="iterations")
    args = parser.parse_args()
    at = "/".join(str(i) for i in args.at)
    print(
        f"| run | falls / 1k steps (it. {at}) | reward alive / before a fall (mean) | "
        f"before a fall paid more | best training elite (it. {at}) | critic gap (it. {at}) |"
    )
    print("|---|---|---|---|---|---|")
    for run in args.runs:
        print(reading(run, args.at))


if __name__ == "__main__":
    main()
