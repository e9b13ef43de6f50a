"""Executors: who steps the simulations of VPPO's rollouts and evaluation episodes.

:class:`Executor` (:mod:`~qdil.executors.base`) is the seam VPPO calls.
:class:`LocalExecutor` (:mod:`~qdil.executors.local`, the default) steps the simulations in
this process. :class:`ShardedExecutor` (:mod:`~qdil.executors.sharded`) cuts them into
shards (:mod:`~qdil.executors.shards`) that workers step
(:mod:`~qdil.executors.worker`), and :class:`RayExecutor` (:mod:`~qdil.executors.ray`)
runs those workers as Ray actors, each next to its physics. The head keeps PPO, the reward
model, the bonus counts, pyribs and xNES. Seeds are per simulation and the action noise is
the head's stream replayed by every worker, so a run's results do not depend on the
executor.
"""

from qdil.executors.base import Executor, ExecutorError
from qdil.executors.local import LocalExecutor
from qdil.executors.ray import RayExecutor
from qdil.executors.sharded import ShardedExecutor

__all__ = ["Executor", "ExecutorError", "LocalExecutor", "RayExecutor", "ShardedExecutor"]
