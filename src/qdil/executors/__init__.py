"""Executors: who steps the simulations of VPPO's rollouts and evaluation episodes.

:class:`LocalExecutor` (the default) steps them in this process; :class:`RayExecutor`
spreads them over Ray actors, each owning a contiguous shard of the simulations and
running the policies next to its physics. The head keeps PPO, the reward model, the bonus
counts, pyribs and xNES. Seeds are per simulation and the action noise is the head's stream
replayed by every worker, so a run's results do not depend on the executor.
"""

from qdil.executors.ray import RayExecutor
from qdil.rl.execution import Executor, ExecutorError, LocalExecutor

__all__ = ["Executor", "ExecutorError", "LocalExecutor", "RayExecutor"]
