"""The survival figures of runs, as the diagnosis of issue 49 reads them.

For each run folder: what its rewards paid per step alive and over the last 20 steps
before a fall, at chosen iterations, and over all its iterations how often the steps before
a fall paid more (docs/concepts/survival.md).

Usage::

    python benchmarks/probes/survival_table.py docs/reports/humanoid-survival/runs/* [--every 5]
"""

from __future__ import annotations

import argparse
import csv
import statistics
from pathlib import Path

from qdil.files import open_table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run folders (with metrics.csv)")
    parser.add_argument("--every", type=int, default=5, help="iterations between table rows")
    args = parser.parse_args()
    head = "| run | iteration | alive | before a fall | falls / 1k steps | walk: alive "
    print(head + "| walk: before a fall |")
    print("|---|---|---|---|---|---|---|")
    summaries = []
    for run in args.runs:
        with open_table(run / "metrics.csv") as file:  # a record's is gzipped
            rows = list(csv.DictReader(file))
        figures = [
            {
                k.removeprefix("survival/"): float(v)
                for k, v in row.items()
                if k.startswith("survival/")
            }
            for row in rows
        ]
        for row, f in zip(rows, figures, strict=True):
            i = int(row["iteration"])
            if i == 1 or i % args.every == 0:
                print(
                    f"| {run.name} | {i} | {f['reward_alive']:.2f} | {f['reward_before_fall']:.2f} "
                    f"| {f['falls_per_1k_steps']:.1f} | {f['walk_reward_alive']:.2f} "
                    f"| {f['walk_reward_before_fall']:.2f} |"
                )
        alive = [f["reward_alive"] for f in figures]
        fall = [f["reward_before_fall"] for f in figures]
        more = sum(b > a for a, b in zip(alive, fall, strict=True))
        walk = sum(f["walk_reward_before_fall"] > f["walk_reward_alive"] for f in figures)
        mean_alive, mean_fall = statistics.mean(alive), statistics.mean(fall)
        summaries.append(
            f"| {run.name} | {len(rows)} | {more} | {walk} | {mean_alive:.2f} "
            f"| {mean_fall:.2f} | {mean_fall / mean_alive:.2f} |"
        )
    print()
    head = "| run | iterations | before a fall paid more | walk: the same | mean alive "
    print(head + "| mean before a fall | ratio |")
    print("|---|---|---|---|---|---|---|")
    print("\n".join(summaries))


if __name__ == "__main__":
    main()
