"""Running a sweep's trials on Ray Tune: on this machine by default, or on a Ray cluster.

Each trial is a Tune trial of :func:`qdil.sweeps.trainable.run_trial` with the CPUs (and
GPUs) it asks for; Tune packs them onto the machines and keeps a crashed trial from
stopping the others. A sweep's state lives in its trials' run directories, not in Tune:
running the same command again continues every unfinished run from its checkpoint and
finishes at once the runs that are done.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ray.tune import Callback

from qdil.executors.ray import check_reachable, ray_address
from qdil.sweeps.trials import Trial

if TYPE_CHECKING:
    from qdil.sweeps.search import Search

COLUMNS = ("state", "iteration", "QD-Score", "coverage", "env-steps/s")


@dataclass(frozen=True)
class Resources:
    """What each trial gets, and where the trials run.

    Attributes:
        cpus: CPUs per trial (its physics and torch threads).
        gpus: GPUs per trial (fractions pack several trials onto one GPU).
        address: a Ray cluster's address (``None``: Ray on this machine, or ``RAY_ADDRESS``).
        concurrent: trials at once at most (0: as many as the CPUs and GPUs allow).
    """

    cpus: int = 1
    gpus: float = 0.0
    address: str | None = None
    concurrent: int = 0


def _trainable(config: dict[str, Any]) -> None:  # pragma: no cover - runs in a Ray worker
    from ray import tune

    from qdil.sweeps.trainable import run_trial

    spec = dict(config["trial"])
    trial = Trial(
        Path(spec["recipe"]),
        spec["seed"],
        tuple(tuple(pair) for pair in spec["overrides"]),
        spec["name"],
        Path(spec["root"]),
        Path(spec["cwd"]),
    )
    if "space" in config:  # a search's trial: the sampled options join the overrides
        trial = _sampled(trial, config["space"])
    run_trial(trial, config["threads"], config["episodes"], tune.report, config.get("metric"))


def _sampled(trial: Trial, values: dict[str, Any]) -> Trial:
    """The search's trial with ``values`` of its options, checked and named as planned."""
    import contextlib

    from qdil.sweeps.search import text
    from qdil.sweeps.trainable import TrialError
    from qdil.sweeps.trials import plan_trial

    overrides = [*trial.overrides, *((key, text(value)) for key, value in values.items())]
    where = contextlib.chdir(trial.cwd) if trial.cwd.is_dir() else contextlib.nullcontext()
    try:
        with where:
            planned, _ = plan_trial(trial.recipe, trial.seed, overrides, trial.root)
    except SystemExit as error:
        raise TrialError(str(error)) from None
    return Trial(
        planned.recipe, planned.seed, planned.overrides, planned.name, trial.root, trial.cwd
    )


def run_sweep(
    trials: list[Trial],
    resources: Resources,
    episodes: int,
    name: str,
    search: Search | None = None,
    every: float = 10.0,
) -> Outcome:
    """Run every trial to its end on Ray Tune; returns the failed trials and a search's ranking.

    Args:
        trials: the planned trials (:func:`qdil.sweeps.trials.plan_trials`), absolute roots;
            with a search, the one trial whose options it samples.
        resources: per-trial CPUs and GPUs, and the cluster.
        episodes: re-scoring episodes per elite of each finished trial (0: none).
        name: the sweep's name (Tune's experiment under ``<root>/.tune``).
        search: sample options of ``trials[0]`` with Optuna (None: run ``trials`` as they are).
        every: seconds between two prints of the trials' table.
    """
    from ray import tune

    with ray_session(resources.address):
        specs = [
            {**asdict(t), "recipe": str(t.recipe), "root": str(t.root), "cwd": str(t.cwd)}
            for t in trials
        ]
        names = [t.name for t in trials] if search is None else []
        table = ProgressTable(names, every, searching=search is not None)
        trainable = tune.with_resources(_trainable, {"cpu": resources.cpus, "gpu": resources.gpus})
        space: dict[str, Any] = {"threads": resources.cpus, "episodes": episodes}
        tune_config = tune.TuneConfig(
            reuse_actors=False, max_concurrent_trials=resources.concurrent or None
        )
        if search is None:
            space["trial"] = tune.grid_search(specs)
        else:
            space |= {"trial": specs[0], "metric": search.metric}
            space["space"] = {domain.key: domain.tune() for domain in search.space}
            tune_config = search.tune_config()
        storage = trials[0].root / ".tune"
        run_config = tune.RunConfig(
            name=name,
            storage_path=str(storage),
            failure_config=tune.FailureConfig(max_failures=0, fail_fast=False),
            callbacks=[table],
            verbose=0,
        )
        if search is not None and tune.Tuner.can_restore(storage / name):
            # a stopped search goes on: Optuna's study and its trials are where they were
            tuner = tune.Tuner.restore(str(storage / name), trainable, resume_errored=True)
        else:
            tuner = tune.Tuner(
                trainable, param_space=space, tune_config=tune_config, run_config=run_config
            )
        with _quiet_tune():
            results = tuner.fit()
        table.show(force=True)
    failed = {_name(r): _message(r.error) for r in results if r.error is not None}
    scored = [r for r in results if r.error is None and (r.metrics or {}).get("rescored")]
    ranked = [(_name(r), r.metrics["objective"], r.config.get("space", {})) for r in scored]
    if search is not None:
        ranked.sort(key=lambda row: row[1], reverse=search.mode == "max")
    return Outcome(failed, ranked)


@contextlib.contextmanager
def ray_session(address: str | None) -> Iterator[None]:
    """Ray for the block: joined where this process has it already, else started and ended.

    A spec's stages share one (each stage's sweep joins it), so Ray starts once a sweep.

    Args:
        address: a Ray cluster's address (``None``: Ray on this machine, or ``RAY_ADDRESS``).
    """
    import ray

    check_reachable(address)  # ray.init would wait minutes for a dead address
    if ray.is_initialized():
        yield
        return
    ray.init(
        address=ray_address(address),
        include_dashboard=False,
        log_to_driver=False,
        logging_level=logging.ERROR,  # not "Started a local Ray instance" and the like
    )
    try:
        yield
    finally:
        ray.shutdown()


@contextlib.contextmanager
def _quiet_tune() -> Iterator[None]:
    """Ray Tune without its own console output: qdil's table says what each trial does.

    Tune's newer output engine prints its experiment banner whatever ``verbose`` says; its
    older one honours ``verbose=0``.
    """
    before = os.environ.get("RAY_AIR_NEW_OUTPUT")
    os.environ["RAY_AIR_NEW_OUTPUT"] = "0"
    try:
        yield
    finally:
        if before is None:
            del os.environ["RAY_AIR_NEW_OUTPUT"]
        else:
            os.environ["RAY_AIR_NEW_OUTPUT"] = before


@dataclass(frozen=True)
class Outcome:
    """What a sweep ended with.

    Attributes:
        failed: each failed trial's error, by run name.
        ranked: a search's re-scored trials, best first: (run name, metric, sampled options).
    """

    failed: dict[str, str]
    ranked: list[tuple[str, float, dict[str, Any]]]


def _message(error: BaseException) -> str:
    """The trial's own error message, without Ray's wrapping of it."""
    cause = getattr(error, "cause", None) or error.__cause__ or error
    return str(cause).strip()


class ProgressTable(Callback):
    """A Tune callback that prints a table of the trials: state, iteration and metrics.

    Args:
        names: the trials' run names, in the sweep's order (a search's trials are added as
            they start, named by their first result).
        every: seconds between two prints (a trial that ends prints at once).
    """

    def __init__(self, names: list[str], every: float, searching: bool = False) -> None:
        self.rows = {name: {"state": "pending"} for name in names}
        self.names: dict[str, str] = {}
        self.every, self.last, self.searching = every, 0.0, searching

    def _row(self, trial: Any, result: dict | None = None) -> dict[str, str]:
        planned = trial.config.get("trial", {}).get("name")
        name = (result or {}).get("run") or self.names.get(trial.trial_id)
        name = name or (planned if planned in self.rows else f"trial {trial.trial_id}")
        old = self.names.get(trial.trial_id)
        if old is not None and old != name and old in self.rows:  # named by its first result
            self.rows[name] = self.rows.pop(old)
        self.names[trial.trial_id] = name
        return self.rows.setdefault(name, {"state": "pending"})

    def on_trial_start(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
        """Mark the trial running."""
        self._row(trial)["state"] = "running"

    def on_trial_result(
        self, iteration: int, trials: list, trial: Any, result: dict, **info: Any
    ) -> None:
        """Take the trial's latest iteration's metrics."""
        row = self._row(trial, result)
        if "qd_score" in result:
            row["iteration"] = f"{result['iteration_qd']}"
            row["QD-Score"] = f"{result['qd_score']:.4g}"
            row["coverage"] = f"{100 * result['coverage']:.2f} %"
            row["env-steps/s"] = f"{result['env_steps_per_s']:,.0f}"
        if result.get("rescored"):
            row["re-scored"] = f"{result['objective']:.4g}"
        self.show()

    def on_trial_complete(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
        """Mark the trial finished (or stopped early) and print the table."""
        row = self._row(trial)
        row["state"] = "stopped" if self.searching and "re-scored" not in row else "finished"
        self.show(force=True)

    def on_trial_error(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
        """Mark the trial failed and print the table."""
        self._row(trial)["state"] = "FAILED"
        self.show(force=True)

    def show(self, force: bool = False) -> None:
        """Print the table, at most every ``every`` seconds unless ``force``."""
        if not self.rows or (not force and time.monotonic() - self.last < self.every):
            return
        self.last = time.monotonic()
        columns = COLUMNS + (("re-scored",) if self.searching else ())
        width = max(len(n) for n in self.rows)
        lines = [f"{'run':<{width}}  " + "  ".join(f"{c:>12}" for c in columns)]
        for name, row in self.rows.items():
            cells = "  ".join(f"{row.get(c, '-'):>12}" for c in columns)
            lines.append(f"{name:<{width}}  {cells}")
        print("\n".join(lines) + "\n", file=sys.stderr, flush=True)


def _name(result: Any) -> str:
    """A finished Tune trial's run name."""
    return (result.metrics or {}).get("run") or result.config["trial"]["name"]
