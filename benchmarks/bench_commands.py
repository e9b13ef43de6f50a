"""How long each ``qdil`` command takes as a whole process: start, imports, work, exit.

Every command runs in a fresh interpreter, best of ``--repeats`` (3), in a scratch folder
holding one finished smoke run (made first, untimed). The figure a user waits for is the
whole process, so nothing is subtracted. Prints a Markdown table (docs/benchmarks.md).

    python benchmarks/bench_commands.py [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SMOKE = str(ROOT / "recipes" / "smoke" / "walker_true.yaml")
COMMANDS = [
    ["--help"],
    ["--version"],
    *([command, "--help"] for command in ("eval", "report", "export", "sweep", "render")),
    ["demos", "--help"],
    ["rewards", "--help"],
    ["fit", "--help"],
    ["rewards", "list"],
    ["report", "runs/done", "--out", "report", "--videos", "0"],
    ["eval", "runs/done", "--episodes", "1"],
    ["fit", SMOKE, "--qd.iterations", "1", "--name", "timed"],
]


def seconds(args: list[str], cwd: Path, env: dict[str, str]) -> float:
    """Wall-clock seconds of ``qdil ARGS`` in a process of its own (fails loudly)."""
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "qdil.cli", *args], cwd=cwd, env=env, capture_output=True
    )
    took = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"qdil {' '.join(args)} failed:\n{done.stderr.decode()[-2000:]}")
    return took


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="runs per command (best kept)")
    args = parser.parse_args(argv)
    env = {**os.environ, "WANDB_MODE": "disabled", "QDIL_NUM_THREADS": "1"}
    env.pop("QDIL_PLUGIN_PATH", None)
    with tempfile.TemporaryDirectory() as folder:
        cwd = Path(folder)
        seconds(["fit", SMOKE, "--qd.iterations", "1", "--name", "done"], cwd, env)
        print(f"| command | seconds (best of {args.repeats}) |\n|---|---|")
        for command in COMMANDS:
            best = float("inf")
            for _ in range(args.repeats):
                if command[0] == "fit" and "--help" not in command:
                    subprocess.run(["rm", "-rf", str(cwd / "runs" / "timed")], check=True)
                best = min(best, seconds(command, cwd, env))
            shown = " ".join("RECIPE" if part == SMOKE else part for part in command)
            print(f"| `qdil {shown}` | {best:.2f} |", flush=True)


if __name__ == "__main__":
    main()
