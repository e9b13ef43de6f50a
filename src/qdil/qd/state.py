"""What a run holds: its components (:class:`Run`) and the loop's counters (:class:`LoopState`).

Plain containers, below everything that uses them: :func:`qdil.run.build_run` fills a
``Run``, the QD loop iterates it, checkpoints save and restore it. The component types are
imported for annotations only, so this module costs nothing at import and imports none of
the modules that import it.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

if TYPE_CHECKING:
    import lightning as L
    import torch

    from qdil.config import LoggingConfig, QDConfig
    from qdil.data import TransitionBatch
    from qdil.demos.dataset import DemoSet
    from qdil.envs.vector import LocomotionVectorEnv
    from qdil.executors.base import Executor
    from qdil.qd.archives import RunArchives
    from qdil.qd.scoring import Scorer
    from qdil.rewards.base import RewardModel
    from qdil.seats import GradientEstimator, Scheduler, SearchEmitter


class IterationProgress(Protocol):
    """A progress display the loop updates after every iteration."""

    def update(self, metrics: dict[str, float]) -> None:
        """Show the iteration's metrics."""
        ...

    def close(self) -> None:
        """End the display."""
        ...


class RunTracker(Protocol):
    """What the QD loop asks of its tracker (:class:`qdil.tracking.Tracker`, a floor above)."""

    def progress(self, start: int, total: int) -> IterationProgress:
        """A progress display from iteration ``start`` to ``total``."""
        ...

    def log(self, metrics: dict[str, float], iteration: int, run: Any) -> None:
        """Record one iteration's metrics of ``run``."""
        ...


@dataclass
class LoopState:
    """Counters and the seed stream of a run; all of it goes into checkpoints."""

    iteration: int = 0
    env_steps: int = 0
    seconds: float = 0.0
    rng: np.random.Generator = field(default_factory=np.random.default_rng)

    def next_seed(self) -> int:
        """A fresh seed for the next environment reset."""
        return int(self.rng.integers(2**31 - 1))

    def count(self, env_steps: int, seconds: float) -> None:
        """Add an iteration's simulated env steps and wall seconds to the run's totals."""
        self.env_steps += env_steps
        self.seconds += seconds


@dataclass
class Run:
    """Everything a QD-IL run holds. Built by :func:`~qdil.run.build_run`; looped by ``run_qd``."""

    name: str
    run_dir: Path
    task: str
    seed: int
    qd: QDConfig
    logging: LoggingConfig
    env: LocomotionVectorEnv
    eval_env: LocomotionVectorEnv
    executor: Executor
    scorer: Scorer
    noise: torch.Generator
    """The run's action noise: the estimator's rollouts and the C engine's evaluations."""
    estimator: GradientEstimator | None
    """``None``: gradient-free emitters ask for every solution (``rl: null``)."""
    reward: RewardModel
    reward_optimizers: list[torch.optim.Optimizer]
    fabric: L.Fabric
    scheduler: Scheduler
    emitter: SearchEmitter | None
    """The search emitter the estimator walks (``None`` without an estimator)."""
    archives: RunArchives
    demos: DemoSet | None
    expert: TransitionBatch | None
    state: LoopState
    tracker: RunTracker
    config: dict[str, Any] = field(default_factory=dict)
    """The resolved recipe; checkpoints store it so a resume can tell an edited config.yaml."""
    torch_rng: torch.Tensor | None = None
    """The state of torch's global generator as the run left it (network initialisations,
    the reward model's noise draw from it): :meth:`own_torch_rng` lends it to the generator
    while the run computes, so that a run changes no one else's random state."""

    @contextmanager
    def own_torch_rng(self) -> Iterator[None]:
        """Torch's global generator holds the run's state inside, the caller's after."""
        import torch

        outside = torch.get_rng_state()
        if self.torch_rng is not None:
            torch.set_rng_state(self.torch_rng)
        try:
            yield
        finally:
            self.torch_rng = torch.get_rng_state()
            torch.set_rng_state(outside)
