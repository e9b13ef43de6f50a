"""What MKL's reproducibility mode costs a QD iteration: ``bench_iteration.py`` with and without.

qdil runs MKL in ``AUTO,STRICT`` mode (``qdil.numerics``); ``MKL_CBWR=OFF`` runs it without
one. The mode is fixed at a process's first MKL call, so each measurement is a process of its
own: ``bench_iteration.py`` alternately with the default and with ``MKL_CBWR=OFF``, so that
a drift of the machine's speed falls on both. Prints each round's seconds per iteration and
per component, and the medians' ratio (mode / off).

Usage::

    python benchmarks/bench_numerics.py [RECIPE] [--rounds 3] [--iterations 2] [--KEY VALUE ...]
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ROW = re.compile(r"^\| \**([A-Za-z ]+?)\** \| \**([0-9.]+)\** \|")
CONDITIONS = {"AUTO,STRICT (qdil's default)": None, "OFF": "OFF"}


def measure(recipe: str, iterations: int, mode: str | None, overrides: list[str]) -> dict:
    """Seconds per iteration of each component, from one ``bench_iteration.py`` process."""
    env = {k: v for k, v in os.environ.items() if k != "MKL_CBWR"}
    if mode is not None:
        env["MKL_CBWR"] = mode
    command = [sys.executable, str(ROOT / "benchmarks" / "bench_iteration.py"), recipe]
    command += ["--iterations", str(iterations), *overrides]
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=True)
    return {m.group(1): float(m.group(2)) for m in map(ROW.match, done.stdout.splitlines()) if m}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("recipe", nargs="?", default=str(ROOT / "recipes" / "walker_ppga.yaml"))
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--iterations", type=int, default=2)
    args, overrides = parser.parse_known_args()
    results: dict[str, list[dict]] = {name: [] for name in CONDITIONS}
    for round_ in range(args.rounds):
        for name, mode in CONDITIONS.items():
            times = measure(args.recipe, args.iterations, mode, overrides)
            results[name].append(times)
            print(f"round {round_ + 1}, {name}: {times['iteration']:.2f} s per iteration")
            sys.stdout.flush()
    labels = list(results["OFF"][0])
    print(f"\n# {Path(args.recipe).name}, {args.rounds} rounds of {args.iterations} iterations")
    print("| component | AUTO,STRICT s | OFF s | ratio |\n|---|---|---|---|")
    for label in labels:
        on, off = (statistics.median(r[label] for r in results[n]) for n in CONDITIONS)
        ratio = f"{on / off:.3f}" if off > 0 else "-"
        print(f"| {label} | {on:.2f} | {off:.2f} | {ratio} |")


if __name__ == "__main__":
    main()
