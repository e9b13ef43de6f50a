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
that takes the run continues it bit for bit. Humanoid's expert runs alone, on both cores:
the slot that takes it waits for the other slots' runs to end, and they wait while it
runs. Once it is re-scored, that slot makes the four demonstrations (``qdil demos``, the
paper's pipeline) that Humanoid's WQDIL and GAIL runs wait for, and ships them with the
package (``src/qdil/demos/shipped/``, to commit). A run whose record a
report keeps under ``docs/reports/evidence-<task>/runs/`` is done, on any machine::

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
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = Path("runs") / "evidence"
REPORTS = ROOT / "docs" / "reports"
SHIPPED = ROOT / "src" / "qdil" / "demos" / "shipped"
"""The package's demonstration sets: where a set the queue makes is shipped (to commit)."""
EPISODES = {"HalfCheetah-v5": 12, "Walker2d-v5": 5, "Humanoid-v5": 5}
"""Re-scoring episodes per elite (the protocol's rule for raising them: its page)."""
WAIT = 120.0
"""Seconds a slot waits before it looks again for a run it may start."""


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
    threads: int = 1
    """Physics threads (``--env.num_threads``, ``qdil eval --num-threads``)."""
    alone: bool = False
    """Runs with no other run beside it (it has every core)."""
    demos: str | None = None
    """The demonstration file the run imitates (under ``OUT``, or shipped with the package):
    it waits until it exists."""
    makes_demos: str | None = None
    """The demonstration file ``qdil demos`` makes from this run (under ``OUT``) once it is
    re-scored."""

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


HUMANOID_DEMOS = "humanoid.npz"
# the order is the protocol's: HalfCheetah, then Walker2d; Humanoid follows its expert
QUEUE = (
    _runs("HalfCheetah-v5", "halfcheetah", ("mcwae", "gail", "ppga"), range(3), 50)
    + _runs("Walker2d-v5", "walker", ("mcwae", "gail", "ppga"), range(3, 5), 120, numba_threads=1)
    + [
        Planned(
            "Humanoid-v5", "recipes/humanoid_ppga.yaml", 0, 100, threads=2, alone=True,
            makes_demos=HUMANOID_DEMOS,
        ),
        *(
            Planned(
                "Humanoid-v5", f"recipes/humanoid_{method}.yaml", 0, 100, numba_threads=1,
                demos=HUMANOID_DEMOS,
            )
            for method in ("mcwae", "gail")
        ),
    ]
)  # fmt: skip


def _report(run: Planned) -> Path:
    return REPORTS / f"evidence-{run.task.split('-v')[0].lower()}"


def _record(run: Planned) -> Path:
    return _report(run) / "runs" / run.name / "eval.json"


def _demos(run: Planned) -> Path | None:
    """The demonstrations ``run`` imitates: made here, or shipped with the package."""
    places = [OUT / run.demos, SHIPPED / run.demos] if run.demos else []
    return next((path.resolve() for path in places if path.is_file()), None)


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


def _holder(run: Planned) -> int | None:
    """The live process that holds ``run``'s lock, if any."""
    lock = OUT / f"{run.name}.lock"
    text = lock.read_text().strip() if lock.exists() else ""
    return int(text) if text.isdigit() and _alive(int(text)) else None


def _others_running() -> list[Planned]:
    """Runs that another live slot holds."""
    return [r for r in QUEUE if _holder(r) not in (None, os.getpid())]


def ready(run: Planned) -> bool:
    """Whether ``run`` may start now: its demonstrations exist, and no run that must run
    alone is held by another slot."""
    if run.demos is not None and _demos(run) is None:
        return False
    return not any(other.alone for other in _others_running())


def take(run: Planned) -> bool:
    """Claim ``run`` for this process unless a live slot holds it."""
    lock = OUT / f"{run.name}.lock"
    if _holder(run) not in (None, os.getpid()):
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
        if run.demos is not None:
            command += ["--demos.path", str(_demos(run))]
    command += ["--env.num_threads", str(run.threads), "--logging.checkpoint_every", "10"]
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
    evaluate = ["eval", str(folder), "--episodes", episodes, "--num-threads", str(run.threads)]
    print(f"{prefix}qdil", " ".join(evaluate), flush=True)
    subprocess.run([sys.executable, "-m", "qdil.cli", *evaluate], check=True, env=env)
    if run.makes_demos is not None and not (OUT / run.makes_demos).is_file():
        demos = ["demos", str(folder), "--out", str(OUT / run.makes_demos)]
        print(f"{prefix}qdil", " ".join(demos), flush=True)
        subprocess.run([sys.executable, "-m", "qdil.cli", *demos], check=True, env=env)
        # shipped (to commit): the protocol ships the set, and the imitation runs need the
        # same file on a machine that replaces this one
        shutil.copyfile(OUT / run.makes_demos, SHIPPED / run.makes_demos)


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
        todo = sorted((run for run in QUEUE if not progress(run)[1]), key=_order)
        mine = next((run for run in todo if ready(run) and take(run)), None)
        if mine is None:
            waiting = [run.name for run in todo if _holder(run) is None]
            if not waiting:
                print("nothing left to take", flush=True)
                return
            print(f"waiting for demonstrations or a run alone: {waiting}", flush=True)
            time.sleep(WAIT)
            continue
        while mine.alone and _others_running():  # the other slots' runs end first
            time.sleep(WAIT)
        work(mine)
        (OUT / f"{mine.name}.lock").unlink(missing_ok=True)
        if args.once:
            return


if __name__ == "__main__":
    main()
