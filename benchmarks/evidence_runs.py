"""The evidence runs of docs/evidence-protocol.md: one queue, worked off by parallel slots.

Every run of the protocol is listed here with its recipe, seed and budget, so the queue is
the protocol's own record of what was run. A slot takes the first run that is neither
finished nor taken by another live slot, starts it (or continues it from its checkpoint:
``qdil fit --resume``), re-scores both archives with ``qdil eval`` once it finishes, and
takes the next. Start one slot per core, each in its own session group::

    setsid python benchmarks/evidence_runs.py run > runs/evidence/slot0.log 2>&1 &
    setsid python benchmarks/evidence_runs.py run > runs/evidence/slot1.log 2>&1 &
    python benchmarks/evidence_runs.py status

A killed slot leaves its run at its last checkpoint (every 10 iterations); the next slot
that takes the run continues it bit for bit. A run whose record a report keeps under
``docs/reports/evidence-<task>/runs/`` is done, on any machine::

    qdil report runs/evidence/halfcheetah_* docs/reports/evidence-halfcheetah/runs \
        --out docs/reports/evidence-halfcheetah --force --videos 0

(``--videos 0``: the committed reports keep no videos; six per run were 39 MB for seven
HalfCheetah runs. ``qdil render`` draws any elite of a run from its folder.)
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = Path("runs") / "evidence"
REPORTS = ROOT / "docs" / "reports"
EPISODES = {"HalfCheetah-v5": 12, "Walker2d-v5": 5, "Humanoid-v5": 5}
"""Re-scoring episodes per elite (the protocol's rule for raising them: its page)."""


@dataclass(frozen=True)
class Planned:
    """One run of the protocol."""

    task: str
    recipe: str
    seed: int
    iterations: int
    numba_threads: int | None = None
    """``NUMBA_NUM_THREADS`` of the run's processes (``None``: numba's default, every core).
    At commit e168ef1 it also sets torch's thread count (the protocol's page says why)."""

    @property
    def name(self) -> str:
        return f"{Path(self.recipe).stem}-seed{self.seed}"


def _runs(
    task: str,
    stem: str,
    methods: tuple[str, ...],
    seeds: range,
    its: int,
    numba_threads: int | None = None,
) -> list:
    return [
        Planned(task, f"recipes/{stem}_{method}.yaml", seed, its, numba_threads)
        for seed in seeds
        for method in methods
    ]


# the order is the protocol's: HalfCheetah, then Walker2d; Humanoid follows its expert
QUEUE = _runs("HalfCheetah-v5", "halfcheetah", ("mcwae", "gail", "ppga"), range(3), 50) + _runs(
    "Walker2d-v5", "walker", ("mcwae", "gail", "ppga"), range(3, 5), 120, numba_threads=1
)


def _record(run: Planned) -> Path:
    task = run.task.split("-v")[0].lower()
    return REPORTS / f"evidence-{task}" / "runs" / run.name / "eval.json"


def recorded(run: Planned) -> bool:
    """Whether a report keeps the run's record, re-scored on the task's episodes per elite."""
    if not _record(run).is_file():
        return False
    return json.loads(_record(run).read_text())["episodes_per_elite"] == EPISODES[run.task]


def progress(run: Planned) -> tuple[int, bool]:
    """Iterations logged and whether ``qdil eval`` re-scored the run's last checkpoint."""
    folder = OUT / run.name
    if recorded(run):
        return run.iterations, True
    logged = 0
    if (folder / "metrics.csv").is_file():
        with open(folder / "metrics.csv", newline="") as file:
            logged = max((int(row["iteration"]) for row in csv.DictReader(file)), default=0)
    scored = (folder / "eval.json").is_file()
    if scored:  # scored on the task's episodes, not on fewer from before the 1 % rule
        episodes = json.loads((folder / "eval.json").read_text())["episodes_per_elite"]
        scored = episodes == EPISODES[run.task]
    return logged, scored


def _order(run: Planned) -> int:
    """Cheapest first: a re-scoring alone, then new runs, then runs to redo from scratch."""
    logged, _ = progress(run)
    if logged >= run.iterations and (OUT / run.name / "checkpoints" / "last.pt").exists():
        return 0
    return 2 if _record(run).is_file() else 1


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def take(run: Planned) -> bool:
    """Claim ``run`` for this process unless a live slot holds it."""
    lock = OUT / f"{run.name}.lock"
    if lock.exists() and lock.read_text().strip().isdigit():
        pid = int(lock.read_text())
        if pid != os.getpid() and _alive(pid):
            return False
    lock.write_text(str(os.getpid()))
    return lock.read_text() == str(os.getpid())  # a slot that wrote at the same time loses


def work(run: Planned) -> None:
    """Fit (or continue) ``run`` to its budget, then re-score both archives."""
    folder = OUT / run.name
    logged, _ = progress(run)
    if (folder / "checkpoints" / "last.pt").exists() or (folder / "config.yaml").exists():
        command = ["fit", "--resume", str(folder), "--qd.iterations", str(run.iterations)]
    else:
        command = ["fit", str(ROOT / run.recipe), "--seed", str(run.seed)]
        command += ["--qd.iterations", str(run.iterations), "--name", run.name]
        command += ["--logging.root", str(OUT)]
    command += ["--env.num_threads", "1", "--logging.checkpoint_every", "10"]
    command += ["--logging.wandb", "disabled", "--logging.progress", "false"]
    # also at the budget: the resume writes the budget into config.yaml (a run begun with
    # another target stops at its checkpoint there; nothing else depends on the target)
    env, prefix = dict(os.environ), ""
    if run.numba_threads is not None:
        env["NUMBA_NUM_THREADS"] = str(run.numba_threads)
        prefix = f"NUMBA_NUM_THREADS={run.numba_threads} "
    print(f"{prefix}qdil", " ".join(command), f"# {logged} iterations logged", flush=True)
    subprocess.run([sys.executable, "-m", "qdil.cli", *command], check=True, env=env)
    episodes = str(EPISODES[run.task])
    evaluate = ["eval", str(folder), "--episodes", episodes, "--num-threads", "1"]
    print(f"{prefix}qdil", " ".join(evaluate), flush=True)
    subprocess.run([sys.executable, "-m", "qdil.cli", *evaluate], check=True, env=env)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("action", choices=("run", "status"))
    parser.add_argument("--once", action="store_true", help="stop after one run")
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    if args.action == "status":
        for run in QUEUE:
            logged, scored = progress(run)
            state = "re-scored" if scored else ""
            if _record(run).is_file() and not scored:
                state = "recorded on other episodes: to redo"
            print(f"{run.name:34s} {logged:4d}/{run.iterations} {state}")
        return
    while True:
        todo = [run for run in QUEUE if not progress(run)[1]]
        todo.sort(key=_order)
        mine = next((run for run in todo if take(run)), None)
        if mine is None:
            print("nothing left to take", flush=True)
            return
        work(mine)
        (OUT / f"{mine.name}.lock").unlink(missing_ok=True)
        if args.once:
            return


if __name__ == "__main__":
    main()
