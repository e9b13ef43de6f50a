"""The QD loop's seats: what a gradient estimator, an emitter and a scheduler must offer it.

Each seat declares its members once, with their signatures. At run time a seat is a small
abstract class that checks structure, not ancestry: a class fits when it (or a base)
defines every member, so pyribs' classes and a plugin's fit without inheriting from qdil;
the recipe schema types ``rl``, ``qd.emitter`` and ``qd.scheduler`` with them and
:func:`seat_problem` says what a class lacks. A type checker reads the same classes as
protocols (``typing.Protocol``), so it checks the signatures too: ``.ci/run`` runs
basedpyright over ``tests/static/seats_fit.py``. Who does what, and why:
docs/concepts/seats.md.
"""

from __future__ import annotations

from abc import ABC
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from ribs.archives import ArchiveBase

if TYPE_CHECKING:
    import numpy as np
    import torch
    from ribs.typing import Int

    from qdil.data import Rollout
    from qdil.envs.vector import LocomotionVectorEnv
    from qdil.executors import Executor
    from qdil.rl.collect import RewardFn
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
    """A place in the loop that any class with the seat's members fills.

    A seat's members are the methods and properties its body declares (and its bases'),
    in their order; :meth:`lacking` looks for them by name.
    """

    title: ClassVar[str] = "component"
    members: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        declared = [
            name
            for name, value in vars(cls).items()
            if not name.startswith("_") and (callable(value) or isinstance(value, property))
        ]
        cls.members = tuple(dict.fromkeys([*cls.members, *declared]))

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


if TYPE_CHECKING:
    from typing import Protocol as SeatBase  # a type checker reads each seat as a protocol
else:
    SeatBase = Seat  # at run time: the structural check above


class GradientEstimator(SeatBase):
    """Estimates ∇f and ∇m_j at the search policy θ_μ and walks θ_μ (PPGA: VPPO).

    An estimator that plays evaluation episodes itself (ES gradients) says how many at once
    in an ``eval_slots`` attribute; the run's evaluation environment holds that many.
    """

    title = "gradient estimator"

    def setup(
        self,
        train_env: LocomotionVectorEnv,
        executor: Executor,
        policy: Any,
        generator: torch.Generator,
        seed: int,
    ) -> None:
        """Bind the training simulations, their executor, the policy family, the noise.

        ``policy`` is the run's ``qdil.config.PolicyConfig`` (the config sits a floor above
        the seats, which it names).
        """
        ...

    def compute_jacobian(
        self, theta: np.ndarray, stats: RunningMeanStd, reward_fn: RewardFn, seed: int
    ) -> PhaseResult:
        """The (k+1, D) gradient estimates at ``theta`` (D,), as ``solutions - theta``."""
        ...

    def walk(
        self,
        theta: np.ndarray,
        stats: RunningMeanStd,
        coefficients: np.ndarray,
        reward_fn: RewardFn,
        seed: int,
    ) -> PhaseResult:
        """θ_μ moved along c_0·∇f + Σ c_j·∇m_j (``coefficients`` (k+1,)), with its stats."""
        ...

    def state_dict(self) -> dict:
        """What a checkpoint keeps."""
        ...

    def load_state_dict(self, state: dict) -> None:
        """Restore what :meth:`state_dict` gave."""
        ...


class Emitter(SeatBase):
    """pyribs' emitter duties: ``ask`` solutions, ``tell`` their results (gradient-free).

    With ``rl: null`` the loop scores whatever the scheduler's emitters ask for and tells
    them (``ribs.emitters.EvolutionStrategyEmitter``: sep-CMA-MAE); with a gradient
    estimator the emitter must also be a :class:`SearchEmitter`.
    """

    title = "emitter"

    @property
    def archive(self) -> ArchiveBase:
        """The archive the scheduler inserts into (pyribs' schedulers read it)."""
        ...

    @property
    def solution_dim(self) -> Int | tuple[Int, ...]:
        """D, the length of a solution (pyribs allows a shape)."""
        ...

    @property
    def batch_size(self) -> Int:
        """Solutions per ``ask``."""
        ...

    def ask(self) -> np.ndarray:
        """(batch_size, D) solutions to score."""
        ...

    def tell(
        self,
        solution: np.ndarray,
        objective: np.ndarray,
        measures: np.ndarray,
        add_info: dict[str, np.ndarray],
        **fields: np.ndarray,
    ) -> None:
        """Their objectives (B,), measures (B, m) and what the archive said of them."""
        ...


class SearchEmitter(Emitter, SeatBase):
    """A DQD emitter with one search policy θ_μ that the estimator walks (PPGA's).

    pyribs' emitter duties plus what the loop needs to score θ_μ and its branches in one
    batch and to walk θ_μ; :meth:`move` is the one way the loop changes θ_μ.
    """

    title = "search emitter"

    def ask_dqd(self) -> np.ndarray:
        """(1, D) θ_μ, whose gradients the estimator computes."""
        ...

    def tell_dqd(
        self,
        solution: np.ndarray,
        objective: np.ndarray,
        measures: np.ndarray,
        jacobian: np.ndarray,
        add_info: dict[str, np.ndarray],
        **fields: np.ndarray,
    ) -> None:
        """θ_μ's objective, measures and (1, k+1, D) Jacobian."""
        ...

    def propose(self, jacobian: np.ndarray) -> np.ndarray:
        """(λ, D) the branches along ``jacobian`` that the next ``ask`` returns."""
        ...

    @property
    def theta(self) -> np.ndarray:
        """(D,) θ_μ."""
        ...

    @property
    def theta_fields(self) -> dict[str, np.ndarray]:
        """θ_μ's observation statistics, the archive's extra fields."""
        ...

    def move(self, solution: np.ndarray, fields: dict[str, np.ndarray]) -> None:
        """θ_μ moves to where the estimator's walk ended, with its statistics."""
        ...

    @property
    def coefficient_mean(self) -> np.ndarray:
        """(k+1,) the walk's weights of ∇f and ∇m_j."""
        ...

    @property
    def restarts(self) -> int:
        """How many times θ_μ restarted at an elite."""
        ...


class Scheduler(SeatBase):
    """Asks its emitters for solutions and tells them the results, inserting into ``archive``.

    pyribs' ``Scheduler`` and ``BanditScheduler`` (which keeps a pool of emitters and asks
    the ones a bandit chooses) both fit; checkpoints pickle it with its archive and emitters.
    """

    title = "scheduler"

    @property
    def archive(self) -> ArchiveBase:
        """The search archive."""
        ...

    def ask(self) -> np.ndarray:
        """(B, D) solutions from its emitters."""
        ...

    def tell(self, objective: np.ndarray, measures: np.ndarray, **fields: np.ndarray) -> None:
        """Their objectives (B,) and measures (B, m), inserted and routed to the emitters."""
        ...


class SearchScheduler(Scheduler, SeatBase):
    """A scheduler of one search emitter that routes the DQD calls too (pyribs' ``Scheduler``).

    The loop finds the search emitter in ``emitters``.
    """

    title = "search scheduler"

    @property
    def emitters(self) -> Sequence[Any]:
        """Its emitters (one search emitter beside an estimator)."""
        ...

    def ask_dqd(self) -> np.ndarray:
        """(1, D) the search emitter's θ_μ."""
        ...

    def tell_dqd(
        self,
        objective: np.ndarray,
        measures: np.ndarray,
        jacobian: np.ndarray,
        **fields: np.ndarray,
    ) -> None:
        """θ_μ's objective (1,), measures (1, m) and Jacobian (1, k+1, D)."""
        ...


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
