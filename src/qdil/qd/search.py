"""The search side of a run: its emitters and the scheduler over the search archive.

Beside a gradient estimator, one search emitter whose θ_μ the estimator walks; without one
(``rl: null``), ``qd.emitters`` gradient-free emitters. docs/concepts/seats.md.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from ribs.schedulers import Scheduler as PyribsScheduler

from qdil.qd.emitter import PPGAEmitter
from qdil.rl.normalize import RunningMeanStd
from qdil.seats import Emitter, Scheduler, SearchEmitter, seat_problem

if TYPE_CHECKING:
    from ribs.archives import ArchiveBase

    from qdil.config import QDConfig


def search_emitters(scheduler: Scheduler) -> list[Emitter]:
    """Every emitter a scheduler may ask (pyribs' ``emitters``, or a bandit's pool)."""
    emitters = getattr(scheduler, "emitters", None)
    return list(emitters if emitters is not None else scheduler.emitter_pool)


def make_search(
    qd: QDConfig,
    main: ArchiveBase,
    x0: np.ndarray,
    obs_dim: int,
    seeds: list[int],
    search: bool,
) -> tuple[SearchEmitter | None, Scheduler]:
    """The emitters that start from ``x0`` and the scheduler over ``main``.

    The recipe schema has checked that the classes fill their seats (:mod:`qdil.seats`);
    beside a gradient estimator (``search``) they must fill the search seats, checked here.

    Args:
        qd: The recipe's ``qd`` section (an emitter or scheduler other than the default,
            ``emitters`` of them).
        main: The CMA-MAE archive the emitters and scheduler insert into.
        x0: The first solution, a ``(solution_dim,)`` array.
        obs_dim: Observation size: θ's observation statistics start empty.
        seeds: One seed per emitter (``qd.emitters`` of them).
        search: The run has a gradient estimator, which walks one search emitter's θ_μ.

    Returns:
        The search emitter (``None`` without an estimator) and the scheduler.

    Raises:
        ValueError: for a class that does not fill its search seat, or ``qd.emitters``
            above 1 beside an estimator, naming the key.
    """
    if search and qd.emitters != 1:
        raise ValueError(
            f"qd.emitters={qd.emitters}: a gradient estimator walks one search emitter; set "
            "qd.emitters to 1, or rl to null for gradient-free emitters"
        )
    make = PPGAEmitter if qd.emitter is None else qd.emitter
    emitters = [make(main, x0=x0, seed=s) for s in seeds]
    scheduler = (
        PyribsScheduler(main, emitters, add_mode="batch")
        if qd.scheduler is None
        else qd.scheduler(main, emitters)
    )
    if not search:
        return None, scheduler
    for key, component in (("qd.emitter", emitters[0]), ("qd.scheduler", scheduler)):
        problem = seat_problem(key, type(component), search=True)
        if problem:
            raise ValueError(f"{key}: {problem}")
    emitter = emitters[0]
    theta_stats = RunningMeanStd(1, (obs_dim,))  # θ_0 has seen no observation yet
    fields = {
        "obs_mean": theta_stats.mean[0].numpy(),
        "obs_var": theta_stats.var[0].numpy(),
        "obs_count": theta_stats.count[0].numpy(),
    }
    emitter.move(emitter.theta, fields)
    return emitter, scheduler
