"""The QD loop's seats: what a gradient estimator, an emitter and a scheduler must offer it.

Each seat is a small abstract class that checks structure, not ancestry: a class fits when
it (or a base) defines every member the seat lists, so pyribs' classes and a plugin's fit
without inheriting from qdil. The recipe schema types ``rl``, ``qd.emitter`` and
``qd.scheduler`` with them; :func:`seat_problem` says what a class lacks. Who does what, and
why: docs/concepts/seats.md.
"""

from __future__ import annotations

from abc import ABC
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from ribs.archives import ArchiveBase

if TYPE_CHECKING:
    import numpy as np

    from qdil.data import Rollout
    from qdil.rl.normalize import RunningMeanStd


@dataclass(frozen=True)
class PhaseResult:
    """What a gradient estimator's phase (the Jacobian, the walk) hands back to the loop.

    Attributes:
        solutions: (P, D) trained solutions (P = k+1 for the Jacobian, 1 for the walk).
        stats: their observation statistics.
        rollouts: the rollouts of the reward-trained policy (copy 0, or the walking θ_μ);
            the reward model updates on the walk's.
        diagnostics: mean diagnostics over the phase (``rl/...`` metrics).
        env_steps: simulated env steps.
    """

    solutions: np.ndarray
    stats: RunningMeanStd
    rollouts: list[Rollout]
    diagnostics: dict[str, float]
    env_steps: int


class Seat(ABC):  # noqa: B024 - no abstract methods: the members are checked by name
    """A place in the loop that any class with the listed members fills."""

    title: ClassVar[str] = "component"
    members: ClassVar[tuple[str, ...]] = ()

    @classmethod
    def lacking(cls, candidate: type) -> list[str]:
        """The members of this seat that ``candidate`` defines nowhere in its bases.

        A member counts if a class in ``candidate``'s MRO defines it or annotates it (an
        attribute set in ``__init__``, declared at class level).
        """
        found: set[str] = set()
        for base in getattr(candidate, "__mro__", ()):
            annotations = vars(base).get("__annotations__")  # a descriptor on ``type`` itself
            found |= set(vars(base)) | set(annotations if isinstance(annotations, dict) else ())
        return [member for member in cls.members if member not in found]

    @classmethod
    def __subclasshook__(cls, candidate: type) -> bool:
        if cls.members and isinstance(candidate, type):
            return not cls.lacking(candidate)
        return NotImplemented


class GradientEstimator(Seat):
    """Estimates ∇f and ∇m_j at the search policy θ_μ and walks θ_μ (PPGA: VPPO).

    Members the loop calls (see :class:`qdil.qd.vppo.VPPO` for their arguments):

    - ``setup(train_env, executor, policy, generator, seed)``: bind the training
      simulations, the executor that steps them, the policy family and the run's noise;
    - ``compute_jacobian(theta, stats, reward_fn, seed) -> PhaseResult``: the (k+1, D)
      gradient estimates as ``solutions - theta``;
    - ``walk(theta, stats, coefficients, reward_fn, seed) -> PhaseResult``: θ_μ moved along
      c_0·∇f + Σ c_j·∇m_j, with its observation statistics;
    - ``state_dict()`` / ``load_state_dict(state)``: what a checkpoint keeps.

    An estimator that plays evaluation episodes itself (ES gradients) says how many at once
    in an ``eval_slots`` attribute; the run's evaluation environment holds that many.
    """

    title = "gradient estimator"
    members = ("setup", "compute_jacobian", "walk", "state_dict", "load_state_dict")


class Emitter(Seat):
    """pyribs' emitter duties: ``ask`` solutions, ``tell`` their results (gradient-free).

    pyribs' schedulers also read ``archive`` (the one they insert into) and ``solution_dim``.

    With ``rl: null`` the loop scores whatever the scheduler's emitters ask for and tells
    them (``ribs.emitters.EvolutionStrategyEmitter``: sep-CMA-MAE); with a gradient
    estimator the emitter must also be a :class:`SearchEmitter`.
    """

    title = "emitter"
    members = ("archive", "solution_dim", "batch_size", "ask", "tell")


class SearchEmitter(Seat):
    """A DQD emitter with one search policy θ_μ that the estimator walks (PPGA's).

    pyribs' emitter duties (``ask_dqd``, ``tell_dqd``, ``ask``, ``tell``, ``batch_size``,
    ``archive``) plus what the loop needs to score θ_μ and its branches in one batch and to
    walk θ_μ: ``propose(jacobian)`` (the branches the next ``ask`` returns), ``theta`` and
    ``theta_fields`` (θ_μ and its observation statistics, read), ``move(solution, fields)``
    (θ_μ moves to where the walk ended: the one way the loop changes it),
    ``coefficient_mean`` (the walk's weights, (k+1,)) and ``restarts`` (a counter).
    """

    title = "search emitter"
    members = (
        "archive",
        "solution_dim",
        "batch_size",
        "ask_dqd",
        "tell_dqd",
        "ask",
        "tell",
        "propose",
        "theta",
        "theta_fields",
        "move",
        "coefficient_mean",
        "restarts",
    )


class Scheduler(Seat):
    """Asks its emitters for solutions and tells them the results, inserting into ``archive``.

    pyribs' ``Scheduler`` and ``BanditScheduler`` (which keeps a pool of emitters and asks
    the ones a bandit chooses) both fit; checkpoints pickle it with its archive and emitters.
    """

    title = "scheduler"
    members = ("archive", "ask", "tell")


class SearchScheduler(Seat):
    """A scheduler of one search emitter that routes the DQD calls too (pyribs' ``Scheduler``).

    The loop with a gradient estimator calls ``ask_dqd()``, ``tell_dqd(objective, measures,
    jacobian, **fields)``, ``ask()`` and ``tell(objective, measures, **fields)``, and finds
    the search emitter in ``emitters``.
    """

    title = "search scheduler"
    members = ("archive", "emitters", "ask_dqd", "tell_dqd", "ask", "tell")


SearchArchive = ArchiveBase
"""The search archive's seat is pyribs' own base class: the CMA-MAE grid today."""

SEATS: dict[str, type[Seat]] = {
    "rl": GradientEstimator,
    "qd.emitter": Emitter,
    "qd.scheduler": Scheduler,
}
"""The recipe keys whose classes fill a seat (with an estimator, the search seats below)."""

SEARCH_SEATS: dict[str, type[Seat]] = {"qd.emitter": SearchEmitter, "qd.scheduler": SearchScheduler}
"""What the emitter and the scheduler must be beside a gradient estimator."""


def seat_problem(key: str, candidate: object, search: bool = False) -> str | None:
    """Why the class ``candidate`` cannot fill the seat at recipe ``key``, or None.

    Args:
        key: a recipe key of :data:`SEATS` (``rl``, ``qd.emitter``, ``qd.scheduler``).
        candidate: the class the recipe names there.
        search: the run has a gradient estimator: the emitter and scheduler must fill
            the search seats (:data:`SEARCH_SEATS`).
    """
    seat = (SEARCH_SEATS if search else {}).get(key) or SEATS.get(key)
    if seat is None or not isinstance(candidate, type):
        return None
    missing = seat.lacking(candidate)
    if not missing:
        return None
    name = f"{candidate.__module__}.{candidate.__qualname__}"
    free = " (a gradient-free one runs with rl: null)" if search and key in SEARCH_SEATS else ""
    return (
        f"{name} is not a {seat.title}: it lacks {', '.join(missing)}{free} "
        f"(qdil.seats.{seat.__name__} lists what the loop calls; docs/concepts/seats.md)"
    )
