"""How long each ``qdil`` command takes as a whole process: start, imports, work, exit.

Every command runs in a fresh interpreter, best of ``--repeats`` (3), in a scratch folder
holding one finished smoke run (made first, untimed). The figure a user waits for is the
whole process, so nothing is subtracted. With ``--against SRC`` (another checkout's
``src``), each command also runs with that tree first on ``PYTHONPATH``, alternating with
this one, so both columns share the machine's state; a command that tree lacks shows "–".
Prints a Markdown table (docs/benchmarks.md).

    python benchmarks/bench_commands.py [--repeats 3] [--against ../base/src]
"""

from __future__ import annotations

import argparse
import os
import shutil
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


def seconds(args: list[str], cwd: Path, env: dict[str, str], strict: bool = True) -> float:
    """Wall-clock seconds of ``qdil ARGS`` in a process of its own.

    A failed command stops the benchmark (``strict``) or counts as NaN (a baseline's).
    """
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "qdil.cli", *args], cwd=cwd, env=env, capture_output=True
    )
    took = time.perf_counter() - start
    if done.returncode == 0:
        return took
    if strict:
        raise SystemExit(f"qdil {' '.join(args)} failed:\n{done.stderr.decode()[-2000:]}")
    return float("nan")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="runs per command (best kept)")
    parser.add_argument("--against", type=Path, help="another checkout's src/ to compare with")
    args = parser.parse_args(argv)
    env = {**os.environ, "WANDB_MODE": "disabled", "QDIL_NUM_THREADS": "1"}
    env.pop("QDIL_PLUGIN_PATH", None)
    trees = {"this tree": env}
    if args.against is not None:
        path = os.pathsep.join(filter(None, [str(args.against.resolve()), env.get("PYTHONPATH")]))
        trees = {"baseline": {**env, "PYTHONPATH": path}, **trees}
    with tempfile.TemporaryDirectory() as folder:
        cwd = Path(folder)
        seconds(["fit", SMOKE, "--qd.iterations", "1", "--name", "done"], cwd, env)
        print(f"| command | {' | '.join(trees)} (s, best of {args.repeats}) |")
        print("|---|" + "---|" * len(trees))
        for command in COMMANDS:
            best = dict.fromkeys(trees, float("inf"))
            for _ in range(args.repeats):
                for tree, tree_env in trees.items():  # alternated: the same load for both
                    if command[0] == "fit" and "--help" not in command:
                        shutil.rmtree(cwd / "runs" / "timed", ignore_errors=True)
                    took = seconds(command, cwd, tree_env, strict=tree == "this tree")
                    best[tree] = min(best[tree], took) if took == took else took
            shown = " ".join("RECIPE" if part == SMOKE else part for part in command)
            cells = " | ".join("–" if s != s else f"{s:.2f}" for s in best.values())
            print(f"| `qdil {shown}` | {cells} |", flush=True)


if __name__ == "__main__":
    main()
