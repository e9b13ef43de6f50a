"""benchmarks/evidence_runs.py: the protocol's queue, its locks and the commands it runs."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def runner(tmp_path: Path, monkeypatch):
    spec = importlib.util.spec_from_file_location(
        "evidence_runs", ROOT / "benchmarks" / "evidence_runs.py"
    )
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "evidence_runs", module)  # its dataclass looks it up
    spec.loader.exec_module(module)
    monkeypatch.setattr(module, "REPORTS", tmp_path / "reports")  # not the repository's
    monkeypatch.setattr(module, "SHIPPED", tmp_path / "shipped")
    (tmp_path / "shipped").mkdir()
    monkeypatch.chdir(tmp_path)
    (tmp_path / module.OUT).mkdir(parents=True)
    return module


def test_the_queue_is_the_protocols(runner) -> None:
    by_task: dict[str, set] = {}
    for run in runner.QUEUE:
        by_task.setdefault(run.task, set()).add((run.recipe, run.seed, run.iterations))
        assert (ROOT / run.recipe).is_file()
    assert {seed for _, seed, _ in by_task["HalfCheetah-v5"]} == {0, 1, 2}
    assert {seed for _, seed, _ in by_task["Walker2d-v5"]} == {3, 4}
    # one budget per task (docs/evidence-protocol.md)
    assert {its for _, _, its in by_task["HalfCheetah-v5"]} == {50}
    assert {its for _, _, its in by_task["Walker2d-v5"]} == {120}
    # torch's thread count at e168ef1 follows NUMBA_NUM_THREADS: 1 for Walker2d's runs
    assert {r.numba_threads for r in runner.QUEUE if r.task == "Walker2d-v5"} == {1}
    assert {r.numba_threads for r in runner.QUEUE if r.task == "HalfCheetah-v5"} == {None}
    # Humanoid: the expert alone on both cores, then WQDIL and GAIL from its demonstrations
    expert, *imitators = [r for r in runner.QUEUE if r.task == "Humanoid-v5"]
    assert expert.recipe.endswith("humanoid_ppga.yaml") and expert.alone and expert.threads == 2
    assert sorted(Path(r.recipe).stem for r in imitators) == ["humanoid_gail", "humanoid_mcwae"]
    assert {r.demos for r in imitators} == {expert.makes_demos} != {None}
    assert {r.iterations for r in (expert, *imitators)} == {100}


def test_a_run_held_by_a_live_slot_is_not_taken(runner) -> None:
    run = runner.QUEUE[0]
    lock = runner.OUT / f"{run.name}.lock"
    with subprocess.Popen(["sleep", "30"]) as holder:
        lock.write_text(str(holder.pid))
        assert not runner.take(run)
        holder.kill()
    assert runner.take(run)  # its holder is gone: the lock is stale
    assert lock.read_text() == str(os.getpid())


@pytest.mark.parametrize("walker", [False, True])
def test_each_run_gets_its_thread_setting(runner, monkeypatch, walker: bool) -> None:
    calls = []
    monkeypatch.setattr(
        runner.subprocess, "run", lambda command, check, env: calls.append((command, env))
    )
    run = next(r for r in runner.QUEUE if (r.task == "Walker2d-v5") == walker)
    runner.work(run)
    (fit, fit_env), (evaluate, eval_env) = calls
    assert fit[3:5] == ["fit", str(ROOT / run.recipe)] and evaluate[3] == "eval"
    assert ["--seed", str(run.seed)] == fit[5:7]
    assert "--episodes" in evaluate and str(runner.EPISODES[run.task]) in evaluate
    for env in (fit_env, eval_env):
        expected = "1" if walker else os.environ.get("NUMBA_NUM_THREADS")
        assert env.get("NUMBA_NUM_THREADS") == expected


def test_imitation_waits_for_its_demonstrations_and_every_run_for_one_alone(runner) -> None:
    expert, wqdil, _ = [r for r in runner.QUEUE if r.task == "Humanoid-v5"]
    walker = next(r for r in runner.QUEUE if r.task == "Walker2d-v5")
    assert runner.ready(expert) and runner.ready(walker) and not runner.ready(wqdil)
    (runner.OUT / expert.makes_demos).write_bytes(b"")
    assert runner.ready(wqdil)
    with subprocess.Popen(["sleep", "30"]) as holder:  # another slot runs the expert
        (runner.OUT / f"{expert.name}.lock").write_text(str(holder.pid))
        assert not runner.ready(walker) and not runner.ready(wqdil)
        holder.kill()
    assert runner.ready(walker)  # its slot is gone


def test_the_expert_makes_the_demonstrations_the_imitators_read(runner, monkeypatch) -> None:
    calls = []

    def run(command: list[str], check: bool, env: dict) -> None:
        calls.append(command[3:])
        if command[3] == "demos":  # what `qdil demos` writes
            Path(command[command.index("--out") + 1]).write_bytes(b"demonstrations")

    monkeypatch.setattr(runner.subprocess, "run", run)
    expert, wqdil, _ = [r for r in runner.QUEUE if r.task == "Humanoid-v5"]
    runner.work(expert)
    fit, evaluate, demos = calls
    assert fit[fit.index("--env.num_threads") + 1] == "2"
    assert evaluate[evaluate.index("--num-threads") + 1] == "2"
    assert demos == [
        "demos",
        str(runner.OUT / expert.name),
        "--out",
        str(runner.OUT / "humanoid.npz"),
    ]
    # shipped with the package as well, for a machine that replaces this one
    kept = runner.SHIPPED / "humanoid.npz"
    assert kept.read_bytes() == b"demonstrations"
    calls.clear()
    runner.work(wqdil)
    fit, _ = calls
    path = fit[fit.index("--demos.path") + 1]
    assert path == str((runner.OUT / "humanoid.npz").resolve())
    (runner.OUT / "humanoid.npz").unlink()  # a new machine: only the shipped copy is left
    assert runner.ready(wqdil)
    calls.clear()
    runner.work(wqdil)
    fit, _ = calls
    assert fit[fit.index("--demos.path") + 1] == str(kept.resolve())
