"""Scoring solutions: each one played as a policy, through the run's executor.

The run owns scoring, not the gradient estimator: every emitter's solutions are scored the
same way, whether or not an estimator made them (docs/concepts/seats.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

from qdil.rl.collect import ActionMap, RewardFn
from qdil.rl.episodes import Evaluation, EvaluationGroup
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd

if TYPE_CHECKING:
    from qdil.config import PolicyConfig
    from qdil.envs.vector import LocomotionVectorEnv
    from qdil.executors.base import Executor


class Scorer:
    """Plays solutions as policies over evaluation episodes and scores them.

    Args:
        executor: the run's executor (set up with the run's environments).
        env: an environment of the run: its sizes, action bounds and device.
        policy: the run's policy family.
        generator: the run's action noise, which the C engine's evaluations draw from
            (``docs/concepts/vppo.md``); on a device each group has its own.
    """

    def __init__(
        self,
        executor: Executor,
        env: LocomotionVectorEnv,
        policy: PolicyConfig,
        generator: torch.Generator,
    ) -> None:
        self.executor = executor
        self.device = env.device
        self.obs_dim = env.single_observation_space.shape[0]
        self.action_dim = env.single_action_space.shape[0]
        self.hidden = tuple(policy.hidden)
        self.obs_clip = policy.obs_clip
        self.generator = generator
        self.action_map = ActionMap(
            env.single_action_space.low, env.single_action_space.high, self.device
        )

    def _actor(self, solutions: np.ndarray) -> VectorizedActor:
        actor = VectorizedActor(len(solutions), self.obs_dim, self.action_dim, self.hidden)
        actor = actor.to(self.device)
        actor.set_solutions(solutions)  # exactly the stored policies, log σ included
        return actor

    def evaluate(
        self,
        solutions: np.ndarray,
        stats: RunningMeanStd,
        episodes: int,
        seed: int,
        reward_fn: RewardFn | None = None,
        deterministic: bool = False,
    ) -> Evaluation:
        """Score P solutions (P, D) over ``episodes`` episodes each (see :meth:`evaluate_all`)."""
        return self.evaluate_all([(solutions, stats, episodes, seed)], reward_fn, deterministic)[0]

    def evaluate_all(
        self,
        requests: list[tuple[np.ndarray, RunningMeanStd, int, int]],
        reward_fn: RewardFn | None = None,
        deterministic: bool = False,
    ) -> list[Evaluation]:
        """Score several groups of solutions, each over its own episodes and reset seed.

        On a device the executor plays the groups side by side, each with noise from a
        generator seeded with its reset seed; on the C engine in turns, with noise from the
        run's generator (``docs/concepts/vppo.md``).

        Args:
            requests: ``(solutions (P, D), stats, episodes, seed)`` of each group.
            reward_fn: scores the episodes for the objective; ``None``: the true return.
            deterministic: act with the mean action or sample.

        Returns:
            One evaluation per group, in order.
        """
        groups = []
        for solutions, stats, episodes, seed in requests:
            generator = torch.Generator(device=self.device).manual_seed(seed)
            groups.append(
                EvaluationGroup(
                    self._actor(solutions), stats.to(self.device), episodes, seed, generator
                )
            )
        return self.executor.evaluate_all(groups, reward_fn, deterministic, self.generator)

    def log_probs(
        self, solution: np.ndarray, stats: RunningMeanStd, obs: torch.Tensor, actions: torch.Tensor
    ) -> torch.Tensor:
        """(B,) log π(a | s) of executed actions under one policy (for AIRL's discriminator).

        Args:
            solution: (D,) the policy.
            stats: its observation statistics (one policy).
            obs: (B, obs_dim) raw observations.
            actions: (B, action_dim) executed actions, mapped back to the policy's [-1, 1].
        """
        actor = self._actor(solution[None])
        action_map = self.action_map
        obs, actions, stats = obs.to(self.device), actions.to(self.device), stats.to(self.device)
        policy_actions = (actions - action_map.low) / action_map.half - 1.0
        with torch.no_grad():
            norm = stats.normalize(obs[None].double(), clip=self.obs_clip).float()
            return actor.distribution(norm).log_prob(policy_actions[None]).sum(-1)[0]
