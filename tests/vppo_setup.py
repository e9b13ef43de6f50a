"""The tests' small VPPO: Walker2d at test size, through any executor, and its scorer."""

from __future__ import annotations

from typing import Any

from qdil.envs.vector import LocomotionVectorEnv
from qdil.qd.scoring import Scorer
from qdil.qd.vppo import VPPO
from qdil.run import set_up_policies

SMALL = {
    "rollout_length": 16,
    "jacobian_iterations": 2,
    "walk_iterations": 2,
    "num_minibatches": 2,
    "update_epochs": 2,
}


def make_vppo(
    executor: Any = None,
    num_envs: int = 12,
    eval_envs: int = 8,
    max_episode_steps: int = 20,
    **settings: Any,
) -> tuple[VPPO, Scorer]:
    """VPPO with :data:`SMALL` settings (``settings`` override them) on Walker2d, one
    physics thread, and the scorer of its policies.

    Args:
        executor: the run's executor (None: the local one).
        num_envs: training simulations (12: k+1 = 3 blocks of 4).
        eval_envs: evaluation simulations.
        max_episode_steps: episode length of both.
    """
    algo = VPPO(**(SMALL | settings))
    kwargs = {"max_episode_steps": max_episode_steps, "num_threads": 1}
    train = LocomotionVectorEnv("Walker2d-v5", num_envs, autoreset_mode="SameStep", **kwargs)
    evaluation = LocomotionVectorEnv("Walker2d-v5", eval_envs, autoreset_mode="Disabled", **kwargs)
    _, scorer, _ = set_up_policies(train, evaluation, algo, executor=executor)
    return algo, scorer
