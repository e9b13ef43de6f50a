"""What a change costs a QD iteration: ``bench_iteration.py`` of another commit against this tree.

Checks the base commit out into a temporary git worktree and runs ``bench_iteration.py``
alternately from it and from this work tree, each in a process of its own (the base's
``src`` first on ``PYTHONPATH``), so that a drift of the machine's speed falls on both.
Prints each round's seconds per iteration, then the medians per component and their ratio
(this tree / base).

Usage::

    python benchmarks/bench_commits.py BASE [RECIPE] [--rounds 3] [--iterations 2] \
        [--KEY VALUE ...]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from bench_numerics import ROW

ROOT = Path(__file__).resolve().parents[1]


def measure(tree: Path, recipe: str, iterations: int, overrides: list[str]) -> dict:
    """Seconds per iteration of each component, from one ``bench_iteration.py`` of ``tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree / "src"))
    if Path(recipe).is_relative_to(ROOT):  # each commit's own recipe of that name: its keys
        recipe = str(tree / Path(recipe).relative_to(ROOT))
    command = [sys.executable, str(tree / "benchmarks" / "bench_iteration.py"), recipe]
    command += ["--iterations", str(iterations), *overrides]
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=True, cwd=tree)
    return {m.group(1): float(m.group(2)) for m in map(ROW.match, done.stdout.splitlines()) if m}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("base", help="the commit to compare with (e.g. HEAD~3 or a hash)")
    parser.add_argument("recipe", nargs="?", default=str(ROOT / "recipes" / "walker_ppga.yaml"))
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--iterations", type=int, default=2)
    args, overrides = parser.parse_known_args()
    recipe = str(Path(args.recipe).resolve())
    with tempfile.TemporaryDirectory(prefix="qdil-base-") as folder:
        base = Path(folder) / "base"
        git = ["git", "-C", str(ROOT), "worktree"]
        subprocess.run([*git, "add", "--detach", str(base), args.base], check=True)
        try:
            trees = {f"base {args.base}": base, "this tree": ROOT}
            results: dict[str, list[dict]] = {name: [] for name in trees}
            for round_ in range(args.rounds):
                for name, tree in trees.items():
                    times = measure(tree, recipe, args.iterations, overrides)
                    results[name].append(times)
                    print(f"round {round_ + 1}, {name}: {times['iteration']:.2f} s per iteration")
                    sys.stdout.flush()
        finally:
            subprocess.run([*git, "remove", "--force", str(base)], check=True)
    base_name, this = trees
    print(f"\n# {Path(recipe).name}, {args.rounds} rounds of {args.iterations} iterations")
    print(f"| component | {base_name} s | this tree s | ratio |\n|---|---|---|---|")
    for label in results[base_name][0]:
        old, new = (statistics.median(r[label] for r in results[n]) for n in (base_name, this))
        ratio = f"{new / old:.3f}" if old > 0 else "-"
        print(f"| {label} | {old:.2f} | {new:.2f} | {ratio} |")


if __name__ == "__main__":
    main()
