"""A search over recipe options: Optuna through Ray Tune, with poor trials stopped early.

Each option is searched within a range (``KEY=LOW:HIGH``, ``KEY=log:LOW:HIGH``,
``KEY=int:LOW:HIGH``, ``KEY=choice:A,B,C``). Trials are ranked by a metric of their
re-scored (corrected) archive; early stopping (ASHA) compares the training archive's metric
at each rung, since re-scoring every trial at every rung would cost more than the trials.
A trial stopped early is told to Optuna as pruned, never with its training value.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ray.tune.search.optuna import OptunaSearch

METRICS = ("qd_score", "qd_score_offset", "coverage", "obj_max", "obj_mean")
"""Metrics a search may rank by: the re-scored true-keyed archive's (``eval.json``), and
during training the same column of ``metrics.csv`` (``qd/<metric>``)."""
KINDS = ("log", "int", "choice")


@dataclass(frozen=True)
class Domain:
    """The range of one searched option.

    Attributes:
        key: the recipe key (``rl.init_args.learning_rate``).
        kind: ``uniform``, ``log``, ``int`` or ``choice``.
        values: ``(low, high)`` (both included), or the choices.
    """

    key: str
    kind: str
    values: tuple

    def tune(self) -> Any:
        """The Tune search space of this option."""
        from ray import tune

        low, high = self.values[0], self.values[-1]
        if self.kind == "choice":
            return tune.choice(list(self.values))
        if self.kind == "int":
            return tune.randint(int(low), int(high) + 1)  # Tune's upper end is excluded
        return (tune.loguniform if self.kind == "log" else tune.uniform)(low, high)

    def ends(self) -> list[str]:
        """Values that bound the range, as recipe overrides (checked before a search)."""
        if self.kind == "choice":
            return list(self.values)
        return [text(value) for value in self.values]


def text(value: Any) -> str:
    """A sampled value as a recipe override (floats in full)."""
    return repr(float(value)) if isinstance(value, float) else str(value)


def parse_domain(spec: str) -> Domain:
    """``KEY=LOW:HIGH``, ``KEY=log:LOW:HIGH``, ``KEY=int:LOW:HIGH`` or ``KEY=choice:A,B``.

    Raises:
        SystemExit: a malformed range, naming it and the forms.
    """
    key, equals, body = spec.partition("=")
    forms = "KEY=LOW:HIGH, KEY=log:LOW:HIGH, KEY=int:LOW:HIGH or KEY=choice:A,B,C"
    kind, _, rest = body.partition(":") if body.split(":", 1)[0] in KINDS else ("uniform", "", body)
    if not equals or not key or not rest:
        raise SystemExit(f"qdil sweep: --space {spec!r}: give {forms}")
    if kind == "choice":
        choices = tuple(choice for choice in rest.split(",") if choice)
        if len(choices) < 2:
            raise SystemExit(f"qdil sweep: --space {spec!r}: give two choices or more")
        return Domain(key, kind, choices)
    try:
        number = int if kind == "int" else float
        low, high = (number(part) for part in rest.split(":"))
    except ValueError:
        raise SystemExit(f"qdil sweep: --space {spec!r}: give {forms}") from None
    if not low < high or (kind == "log" and low <= 0):
        raise SystemExit(
            f"qdil sweep: --space {spec!r}: the low end must lie below the high end "
            "(and above 0 on a log scale)"
        )
    return Domain(key, kind, (low, high))


@dataclass(frozen=True)
class Search:
    """An Optuna search, ranked by a re-scored metric.

    Attributes:
        space: the searched options.
        metric: one of :data:`METRICS`, of the re-scored true-keyed archive.
        mode: ``max`` or ``min``.
        samples: trials to run.
        grace: iterations before early stopping may stop a trial (0: no early stopping).
        concurrent: trials at once (0: as many as the CPUs allow).
        iterations: the trials' budget in iterations (where early stopping ends).
    """

    space: tuple[Domain, ...]
    metric: str = "coverage"
    mode: str = "max"
    samples: int = 20
    grace: int = 10
    concurrent: int = 0
    iterations: int = 0

    def __post_init__(self) -> None:
        if self.metric not in METRICS:
            raise SystemExit(f"qdil sweep: --metric {self.metric!r}: choose one of {METRICS}")
        if self.mode not in ("max", "min") or self.samples < 1 or self.grace < 0:
            raise SystemExit("qdil sweep: --mode is max or min, --samples >= 1, --grace >= 0")
        keys = [domain.key for domain in self.space]
        if not keys or len(set(keys)) < len(keys):
            raise SystemExit("qdil sweep: a search needs --space options, each key once")

    def tune_config(self) -> Any:
        """Tune's search settings: Optuna, ASHA up to the budget, and concurrency."""
        import optuna
        from ray import tune
        from ray.tune.schedulers import ASHAScheduler, FIFOScheduler
        from ray.tune.search import ConcurrencyLimiter

        optuna.logging.set_verbosity(optuna.logging.WARNING)  # the sweep prints its own table
        searcher: Any = RescoredOptunaSearch(metric="objective", mode=self.mode)
        if self.concurrent:
            searcher = ConcurrencyLimiter(searcher, max_concurrent=self.concurrent)
        scheduler: Any = FIFOScheduler()
        if self.grace and self.grace < self.iterations:
            scheduler = ASHAScheduler(
                time_attr="iteration_qd",
                metric="objective",
                mode=self.mode,
                max_t=self.iterations + 1,  # the last row must not stop it: it is re-scored next
                grace_period=self.grace,
            )
        return tune.TuneConfig(
            search_alg=searcher, scheduler=scheduler, num_samples=self.samples,
            reuse_actors=False,
        )  # fmt: skip


class RescoredOptunaSearch(OptunaSearch):
    """Ray Tune's ``OptunaSearch``, told each trial's re-scored metric.

    A trial that ends without one (stopped early, or failed) is pruned, not ranked by its
    training value.
    """

    def on_trial_complete(
        self, trial_id: str, result: dict | None = None, error: bool = False
    ) -> None:
        """Tell Optuna the trial's re-scored value, or that it was pruned (or failed)."""
        if result is not None and not result.get("rescored"):
            result = None
        super().on_trial_complete(trial_id, result, error)
