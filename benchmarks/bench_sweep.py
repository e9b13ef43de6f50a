"""What running as a ``qdil sweep`` trial costs a run: the trial against a plain ``qdil fit``.

Alternates, in fresh folders, a plain ``qdil fit RECIPE --qd.iterations N`` and a one-trial
``qdil sweep RECIPE --seeds 0 --cpus-per-trial C --episodes 0 --qd.iterations N`` (the same
run: both cores for its physics by default), and prints each round's seconds per iteration
(``perf/iter_seconds``, its first iteration left out: kernels compile there) and wall
seconds of the whole command, then the medians' ratio (sweep / plain).

Usage::

    python benchmarks/bench_sweep.py [RECIPE] [--rounds 2] [--iterations 4] [--cpus 2]
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def measure(command: list[str], folder: Path) -> tuple[float, float]:
    """Median seconds per iteration after the first, and the command's wall seconds."""
    env = dict(os.environ, WANDB_MODE="disabled")
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "qdil.cli", *command], cwd=folder, env=env,
                   check=True, capture_output=True)  # fmt: skip
    wall = time.perf_counter() - start
    (metrics,) = folder.glob("runs/*/metrics.csv")
    with open(metrics, newline="") as file:
        seconds = [float(row["perf/iter_seconds"]) for row in csv.DictReader(file)]
    return statistics.median(seconds[1:]), wall


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("recipe", nargs="?", default=str(ROOT / "recipes" / "walker_ppga.yaml"))
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--iterations", type=int, default=4)
    parser.add_argument("--cpus", type=int, default=2)
    args = parser.parse_args()
    recipe = str(Path(args.recipe).resolve())
    budget = ["--qd.iterations", str(args.iterations), "--logging.progress", "false"]
    commands = {
        "plain qdil fit": ["fit", recipe, *budget],
        "sweep trial": ["sweep", recipe, "--seeds", "0", "--episodes", "0",
                        "--cpus-per-trial", str(args.cpus), *budget],
    }  # fmt: skip
    results: dict[str, list[tuple[float, float]]] = {name: [] for name in commands}
    for round_ in range(args.rounds):
        for name, command in commands.items():
            with tempfile.TemporaryDirectory() as folder:
                results[name].append(measure(command, Path(folder)))
            per, wall = results[name][-1]
            print(f"round {round_ + 1}, {name}: {per:.2f} s per iteration, {wall:.1f} s wall")
            sys.stdout.flush()
    print(f"\n# {Path(recipe).name}, {args.rounds} rounds of {args.iterations} iterations")
    print("| | plain qdil fit | sweep trial | ratio |\n|---|---|---|---|")
    for i, label in enumerate(("s per iteration (median, after the first)", "wall s")):
        plain, trial = (statistics.median(r[i] for r in results[n]) for n in commands)
        print(f"| {label} | {plain:.2f} | {trial:.2f} | {trial / plain:.3f} |")


if __name__ == "__main__":
    main()
