"""Running a sweep's trials on Ray Tune: on this machine by default, or on a Ray cluster.

Each trial is a Tune trial of :func:`qdil.sweeps.trainable.run_trial` with the CPUs (and
GPUs) it asks for; Tune packs them onto the machines and keeps a crashed trial from
stopping the others. A sweep's state lives in its trials' run directories, not in Tune:
running the same command again continues every unfinished run from its checkpoint and
finishes at once the runs that are done.
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from ray.tune import Callback

from qdil.sweeps.trials import Trial

COLUMNS = ("state", "iteration", "QD-Score", "coverage", "env-steps/s")


@dataclass(frozen=True)
class Resources:
    """What each trial gets, and where the trials run.

    Attributes:
        cpus: CPUs per trial (its physics and torch threads).
        gpus: GPUs per trial (fractions pack several trials onto one GPU).
        address: a Ray cluster's address (``None``: Ray on this machine, or ``RAY_ADDRESS``).
    """

    cpus: int = 1
    gpus: float = 0.0
    address: str | None = None


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
    run_trial(trial, config["threads"], config["episodes"], tune.report)


def run_sweep(
    trials: list[Trial], resources: Resources, episodes: int, name: str, every: float = 10.0
) -> dict[str, str]:
    """Run every trial to its end on Ray Tune; returns the failed trials' errors by name.

    Args:
        trials: the planned trials (:func:`qdil.sweeps.trials.plan_trials`), absolute roots.
        resources: per-trial CPUs and GPUs, and the cluster.
        episodes: re-scoring episodes per elite of each finished trial (0: none).
        name: the sweep's name (Tune's experiment under ``<root>/.tune``).
        every: seconds between two prints of the trials' table.
    """
    import ray
    from ray import tune

    started = not ray.is_initialized()
    if started:
        ray.init(address=resources.address, include_dashboard=False, log_to_driver=False)
    try:
        specs = [
            {**asdict(t), "recipe": str(t.recipe), "root": str(t.root), "cwd": str(t.cwd)}
            for t in trials
        ]
        table = ProgressTable([t.name for t in trials], every)
        tuner = tune.Tuner(
            tune.with_resources(_trainable, {"cpu": resources.cpus, "gpu": resources.gpus}),
            param_space={
                "trial": tune.grid_search(specs),
                "threads": resources.cpus,
                "episodes": episodes,
            },
            tune_config=tune.TuneConfig(reuse_actors=False),
            run_config=tune.RunConfig(
                name=name,
                storage_path=str(trials[0].root / ".tune"),
                failure_config=tune.FailureConfig(max_failures=0, fail_fast=False),
                callbacks=[table],
                verbose=0,
            ),
        )
        results = tuner.fit()
        table.show(force=True)
    finally:
        if started:
            ray.shutdown()
    return {
        result.config["trial"]["name"]: _message(result.error)
        for result in results
        if result.error is not None
    }


def _message(error: BaseException) -> str:
    """The trial's own error message, without Ray's wrapping of it."""
    cause = getattr(error, "cause", None) or error.__cause__ or error
    return str(cause).strip()


class ProgressTable(Callback):
    """A Tune callback that prints a table of the trials: state, iteration and metrics.

    Args:
        names: the trials' run names, in the sweep's order.
        every: seconds between two prints (a trial that ends prints at once).
    """

    def __init__(self, names: list[str], every: float) -> None:
        self.rows = {name: {"state": "pending"} for name in names}
        self.every, self.last = every, 0.0

    def on_trial_start(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
        """Mark the trial running."""
        self.rows[_name(trial)]["state"] = "running"

    def on_trial_result(
        self, iteration: int, trials: list, trial: Any, result: dict, **info: Any
    ) -> None:
        """Take the trial's latest iteration's metrics."""
        row = self.rows[_name(trial)]
        if "iteration_qd" in result:
            row["iteration"] = f"{result['iteration_qd']}"
            row["QD-Score"] = f"{result['qd_score']:.4g}"
            row["coverage"] = f"{100 * result['coverage']:.2f} %"
            row["env-steps/s"] = f"{result['env_steps_per_s']:,.0f}"
        self.show()

    def on_trial_complete(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
        """Mark the trial finished and print the table."""
        self.rows[_name(trial)]["state"] = "finished"
        self.show(force=True)

    def on_trial_error(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
        """Mark the trial failed and print the table."""
        self.rows[_name(trial)]["state"] = "FAILED"
        self.show(force=True)

    def show(self, force: bool = False) -> None:
        """Print the table, at most every ``every`` seconds unless ``force``."""
        if not force and time.monotonic() - self.last < self.every:
            return
        self.last = time.monotonic()
        width = max(len(n) for n in self.rows)
        lines = [f"{'run':<{width}}  " + "  ".join(f"{c:>12}" for c in COLUMNS)]
        for name, row in self.rows.items():
            cells = "  ".join(f"{row.get(c, '-'):>12}" for c in COLUMNS)
            lines.append(f"{name:<{width}}  {cells}")
        print("\n".join(lines) + "\n", file=sys.stderr, flush=True)


def _name(trial: Any) -> str:
    return trial.config["trial"]["name"]
