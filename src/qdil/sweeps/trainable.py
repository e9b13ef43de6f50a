"""One trial of a sweep, as Ray Tune runs it: ``qdil fit``, then ``qdil eval``, in a child process.

The child runs the commands a user would type (so a trial equals ``qdil fit`` of its recipe,
seed and options, bit for bit: :mod:`qdil.cli.trial`), with ``--env.num_threads`` set to
the trial's CPUs. While it
runs, each new row of the run's ``metrics.csv`` is reported to Tune. A lock on the run's
folder (:func:`guard`), held by the trial and its child, keeps any second process out, and
the child dies with the trial's thread (Linux's parent-death signal), so a killed sweep
leaves no run going on alone.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from functools import partial
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from qdil.files import CONFIG_NAME
from qdil.sweeps.follow import MetricsFollower, last_iteration
from qdil.sweeps.trials import Trial

LOCKS = ".locks"
"""The folder under the runs folder where each run's guard lives (``<name>.lock``)."""
REPORTED = {
    "qd/qd_score": "qd_score",
    "qd/coverage": "coverage",
    "perf/sps": "env_steps_per_s",
    "perf/env_steps": "env_steps",
}
"""``metrics.csv`` columns a trial reports to Tune, and their names there."""


class TrialError(RuntimeError):
    """A trial's ``qdil`` command failed; the message holds the end of its output."""


@contextlib.contextmanager
def guard(trial: Trial) -> Iterator[int]:
    """Hold the run folder's lock for as long as the block runs; yields its descriptor.

    Raises:
        TrialError: another process holds it (another sweep, or a run of the same name).
    """
    folder = trial.root / LOCKS
    folder.mkdir(parents=True, exist_ok=True)
    fd = os.open(folder / f"{trial.name}.lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise TrialError(
            f"{trial.run_dir} is being written by another process (its lock "
            f"{folder / trial.name}.lock is held); wait for it or stop it"
        ) from None
    try:
        yield fd
    finally:
        os.close(fd)  # the child, holding a copy, keeps it until it exits


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG


def run_commands(
    fit: list[str], episodes: int, run_dir: Path, lock: int, threads: int, log: Path, cwd: Path
) -> None:
    """``qdil FIT``, then its ``qdil eval`` where due, in one child process.

    The child (:mod:`qdil.cli.trial`) holds ``lock`` and dies with this thread.

    It runs in ``cwd`` where that folder exists here (a cluster node without it: in Ray's
    working folder, where relative paths then fail with the child's own error).

    Raises:
        TrialError: a command failed, with the end of its output.
    """
    env = dict(os.environ, QDIL_NUM_THREADS=str(threads), OMP_NUM_THREADS=str(threads))
    address = _cluster_address()
    if address is not None:  # a trial's Ray executor (address null or auto) joins the sweep's
        env["RAY_ADDRESS"] = address
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "ab") as out:
        out.write(f"$ qdil {' '.join(fit)}\n# started {now()}\n".encode())
        if os.environ.get("CUDA_VISIBLE_DEVICES"):  # set by Ray for a trial given GPUs
            out.write(f"# the GPUs Ray gave this trial: {_gpus()}\n".encode())
        out.flush()
        done = subprocess.run(
            [sys.executable, "-m", "qdil.cli.trial", str(run_dir), str(episodes), *fit],
            stdout=out,
            stderr=subprocess.STDOUT,
            env=env,
            pass_fds=(lock,),
            cwd=cwd if cwd.is_dir() else None,
            preexec_fn=_die_with_parent if sys.platform == "linux" else None,
            check=False,
        )
        out.write(f"# ended {now()} with exit status {done.returncode}\n".encode())
    if done.returncode:
        tail = log.read_text(errors="replace")[-3000:]
        raise TrialError(f"the trial's qdil command exited with {done.returncode}; its output "
                         f"ends:\n{tail}")  # fmt: skip


def now() -> str:
    """Wall-clock time for the trial's log: ISO 8601 and Unix seconds (what tests compare)."""
    seconds = time.time()
    stamp = time.strftime("%Y-%m-%dT%H:%M:%S%z", time.localtime(seconds))
    return f"{stamp} (unix {seconds:.3f})"


def _gpus() -> str:
    """``CUDA_VISIBLE_DEVICES`` and this trial's share of each GPU, as Ray assigned them."""
    visible = os.environ.get("CUDA_VISIBLE_DEVICES", "")
    try:
        import ray

        share = ray.get_runtime_context().get_assigned_resources().get("GPU")
    except Exception:  # outside a Ray worker: the variable alone
        share = None
    return f"CUDA_VISIBLE_DEVICES={visible}" + (f", GPU share {share:g}" if share else "")


def _cluster_address() -> str | None:
    """The Ray cluster this process is a worker of (None outside Ray)."""
    try:
        import ray

        return ray.get_runtime_context().gcs_address if ray.is_initialized() else None
    except ImportError:
        return None


def follow(
    rows: MetricsFollower, report: Callable[[dict[str, Any]], None], metric: str | None = None
) -> None:
    """Report the rows appended to a trial's ``metrics.csv`` since the last look.

    With a search's ``metric``, each row also reports the training archive's value of it
    as ``objective`` (what early stopping compares).
    """
    for row in rows.rows():
        values = {name: _number(row.get(column)) for column, name in REPORTED.items()}
        if metric is not None:
            values["objective"] = _number(row.get(f"qd/{metric}"))
        run = rows.path.parent.name
        report({"iteration_qd": int(float(row["iteration"])), "run": run, **values})


def _number(value: str | None) -> float:
    try:
        return float(value) if value not in (None, "") else float("nan")
    except ValueError:
        return float("nan")


def rescored(run_dir: Path, episodes: int, iteration: int | None = None) -> bool:
    """Whether the run's ``eval.json`` scores its last checkpoint with ``episodes`` episodes.

    ``iteration``: the checkpoint's, where the caller has read it already.
    """
    from qdil.qd.checkpoint import CHECKPOINT, read_checkpoint

    try:
        summary = json.loads((run_dir / "eval.json").read_text())
        if iteration is None:
            iteration = read_checkpoint(run_dir / CHECKPOINT)["iteration"]
    except (OSError, ValueError, KeyError, RuntimeError):
        return False
    return summary.get("iteration") == iteration and summary.get("episodes_per_elite") == episodes


def finished_and_rescored(trial: Trial, episodes: int) -> bool:
    """Whether the trial's run is done: finished, and re-scored where ``episodes`` asks.

    Finished as its ``qdil fit --resume`` would find it: the checkpoint against the stored
    recipe's ``qd.iterations`` and ``qd.env_steps``, or the trial's overrides of them (the
    planning already refused a folder of another configuration). Such a trial's child would
    only read the run and say so: a finished sweep run again starts no process.
    """
    import yaml

    from qdil.config import finished
    from qdil.qd.checkpoint import CHECKPOINT, read_checkpoint

    try:
        qd = dict(yaml.safe_load((trial.run_dir / CONFIG_NAME).read_text())["qd"])
        state = read_checkpoint(trial.run_dir / CHECKPOINT)
        for key, value in trial.overrides:
            if key in ("qd.iterations", "qd.env_steps"):
                qd[key.removeprefix("qd.")] = yaml.safe_load(value)
        limits = SimpleNamespace(iterations=int(qd["iterations"]), env_steps=qd.get("env_steps"))
        done = finished(limits, state["iteration"], state["env_steps"])
    except (OSError, ValueError, KeyError, TypeError, RuntimeError, yaml.YAMLError):
        return False  # the child reads it and says what is wrong
    return done and (episodes == 0 or rescored(trial.run_dir, episodes, state["iteration"]))


def run_trial(
    trial: Trial,
    threads: int,
    episodes: int,
    report: Callable[[dict[str, Any]], None],
    metric: str | None = None,
    every: float = 5.0,
) -> None:
    """Start or continue the trial's run to its end, then re-score it (``episodes`` > 0).

    Args:
        trial: the trial.
        threads: its CPUs: physics threads (``env.num_threads``) and torch's.
        episodes: re-scoring episodes per elite (0: no re-scoring).
        report: called with each new iteration's metrics, then with ``done`` (and, for a
            search, ``rescored`` and the re-scored ``objective``).
        metric: a search's metric (:data:`qdil.sweeps.search.METRICS`), or None.
        every: seconds between two looks at ``metrics.csv``.

    Raises:
        TrialError: a command failed, or another process holds the run's folder.
    """
    log = trial.root / LOCKS / f"{trial.name}.log"
    metrics = trial.run_dir / "metrics.csv"
    with guard(trial) as lock:
        fit = ["fit", *trial.fit_args(), "--env.num_threads", str(threads)]
        # rows a resumed run keeps are not reported again, but the last one is (the table)
        resumed = (trial.run_dir / CONFIG_NAME).is_file()
        rows = MetricsFollower(metrics, max(0, last_iteration(metrics) - 1) if resumed else 0)
        if resumed and finished_and_rescored(trial, episodes):
            with open(log, "a") as out:
                out.write(f"# {now()}: finished and re-scored already; nothing to run\n")
        else:
            work = partial(
                run_commands, fit, episodes, trial.run_dir, lock, threads, log, trial.cwd
            )
            with _in_background(work) as finished:
                while not finished(every):  # a finished command ends the wait at once
                    follow(rows, report, metric)
        follow(rows, report, metric)
    report({"done": 1.0, **(_rescored(trial.run_dir, metric) if metric else {})})


def _rescored(run_dir: Path, metric: str) -> dict[str, Any]:
    """A search trial's last result: its re-scored ``objective`` and iteration."""
    summary = json.loads((run_dir / "eval.json").read_text())
    objective = float(summary["metrics"][metric])
    iteration = summary["iteration"]
    return {"rescored": 1, "objective": objective, "iteration_qd": iteration, "run": run_dir.name}


@contextlib.contextmanager
def _in_background(work: Callable[[], None]) -> Iterator[Callable[[float], bool]]:
    """Run ``work`` in a thread; re-raise its error after.

    Yields a wait of at most so many seconds that says whether ``work`` finished.
    """
    import threading

    errors: list[BaseException] = []

    def target() -> None:
        try:
            work()
        except BaseException as error:  # re-raised in the trial's thread
            errors.append(error)

    thread = threading.Thread(target=target, daemon=True)
    thread.start()

    def finished(seconds: float) -> bool:
        thread.join(seconds)
        return not thread.is_alive()

    yield finished
    thread.join()
    if errors:
        raise errors[0]
