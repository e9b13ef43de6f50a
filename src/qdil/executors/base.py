"""The executor seam: who steps the simulations of VPPO's rollouts and evaluation episodes.

VPPO hands its policies to an :class:`Executor` and gets rollouts and scores back; it keeps
PPO, and the QD loop keeps the reward model, pyribs and xNES. The executors are
:class:`~qdil.executors.local.LocalExecutor` (the default, this process),
:class:`~qdil.executors.sharded.ShardedExecutor` and its transport
:class:`~qdil.executors.ray.RayExecutor`.
"""

from __future__ import annotations

import abc

import torch

from qdil.data import Rollout
from qdil.envs.vector import LocomotionVectorEnv
from qdil.rl.collect import PolicyData, RewardFn
from qdil.rl.episodes import Evaluation, EvaluationGroup
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd


class ExecutorError(RuntimeError):
    """Execution failed in a way the run cannot recover from by itself (the message says why)."""


class Executor(abc.ABC):
    """Runs VPPO's training rollouts and evaluation episodes; VPPO keeps everything else.

    Every executor returns the same tensors for the same inputs: the same rollouts,
    bit for bit, as :class:`~qdil.rl.collect.Collector` and
    :func:`~qdil.rl.episodes.evaluate_policies` on the head's environments, and it draws
    the same action noise from ``generator``, leaving it in the same state.
    """

    @abc.abstractmethod
    def setup(
        self, train_env: LocomotionVectorEnv, eval_env: LocomotionVectorEnv, obs_clip: float
    ) -> None:
        """Bind the head's environments (their sizes and tasks) and the observation clip."""

    @abc.abstractmethod
    def start(self, seed: int) -> None:
        """Reset every training simulation (simulation i with ``seed + i``)."""

    @abc.abstractmethod
    def collect(
        self,
        actor: VectorizedActor,
        stats: RunningMeanStd,
        num_steps: int,
        generator: torch.Generator,
        update_stats: bool,
    ) -> tuple[Rollout, PolicyData]:
        """Roll out ``num_steps`` steps of P policies (see ``Collector.collect``)."""

    @abc.abstractmethod
    def pop_episode_stats(self) -> tuple[list[float], list[int]]:
        """Returns and lengths of the training episodes finished since the last call."""

    @abc.abstractmethod
    def evaluate(
        self,
        actor: VectorizedActor,
        stats: RunningMeanStd,
        episodes: int,
        seed: int,
        reward_fn: RewardFn | None,
        deterministic: bool,
        generator: torch.Generator,
    ) -> Evaluation:
        """Score P policies over ``episodes`` episodes each (see ``evaluate_policies``)."""

    def evaluate_all(
        self,
        groups: list[EvaluationGroup],
        reward_fn: RewardFn | None,
        deterministic: bool,
        generator: torch.Generator,
    ) -> list[Evaluation]:
        """Score several groups of policies, one after the other, noise from ``generator``.

        An executor that plays them side by side (``LocalExecutor`` on a device)
        overrides it and draws each group's noise from the group's own generator instead.
        """
        return [
            self.evaluate(g.actor, g.stats, g.episodes, g.seed, reward_fn, deterministic, generator)
            for g in groups
        ]

    @abc.abstractmethod
    def close(self) -> None:
        """Release the workers, if any."""
