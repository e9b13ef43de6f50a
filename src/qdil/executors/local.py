"""Stepping every simulation in this process, through the torch face that fits the physics.

:class:`LocalExecutor` is the default executor: a recipe without an ``executor`` section
runs with it, on the C engine's host face or on a device (:func:`qdil.envs.faces.torch_face`).
"""

from __future__ import annotations

import torch
from typing_extensions import override

from qdil.data import Rollout
from qdil.envs.faces import torch_face
from qdil.envs.vector import LocomotionVectorEnv
from qdil.executors.base import Executor
from qdil.rl.collect import Collector, PolicyData, RewardFn
from qdil.rl.episodes import Evaluation, EvaluationGroup, evaluate_groups
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd


class LocalExecutor(Executor):
    """Steps every simulation here, through the torch face that fits the physics.

    The C engine's host face (physics threaded by ``env.num_threads``) or the device face
    (:func:`~qdil.envs.faces.torch_face`): rollouts and evaluations never copy a step to
    the host on a device.
    """

    @override
    def setup(
        self, train_env: LocomotionVectorEnv, eval_env: LocomotionVectorEnv, obs_clip: float
    ) -> None:
        """Bind the environments' faces; the training one keeps its state across ``collect``.

        Raises:
            ValueError: if the two environments step on different devices (naming
                ``env.device``).
        """
        if eval_env.device != train_env.device:
            raise ValueError(
                f"env.device: the training physics steps on {train_env.device} but the "
                f"evaluations' on {eval_env.device}; one env.device places both"
            )
        self.collector = Collector(torch_face(train_env), obs_clip)
        self.eval_face = torch_face(eval_env)
        self.obs_clip = obs_clip

    @override
    def start(self, seed: int) -> None:
        self.collector.start(seed)

    @override
    def collect(
        self,
        actor: VectorizedActor,
        stats: RunningMeanStd,
        num_steps: int,
        generator: torch.Generator,
        update_stats: bool,
    ) -> tuple[Rollout, PolicyData]:
        return self.collector.collect(actor, stats, num_steps, generator, update_stats)

    @override
    def pop_episode_stats(self) -> tuple[list[float], list[int]]:
        return self.collector.pop_episode_stats()

    @override
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
        group = EvaluationGroup(actor, stats, episodes, seed, generator)
        return evaluate_groups(self.eval_face, [group], reward_fn, deterministic, self.obs_clip)[0]

    @override
    def evaluate_all(
        self,
        groups: list[EvaluationGroup],
        reward_fn: RewardFn | None,
        deterministic: bool,
        generator: torch.Generator,
    ) -> list[Evaluation]:
        """Score the groups: side by side on a device, else one after the other.

        On a device (the face's ``side_by_side``) one batch takes as many steps in sequence
        as the longest group's episodes, not their sum. Each group draws its noise from its
        own generator there (``generator`` is left alone), so its result is the same as
        alone (``evaluate_groups``); without room for all of them (``env.eval_envs`` below
        their sum) the groups are played one after the other, with the same noise. The C
        engine plays them in turns with ``generator``'s noise (:meth:`Executor.evaluate_all`).
        """
        face = self.eval_face
        if not face.side_by_side:
            return super().evaluate_all(groups, reward_fn, deterministic, generator)
        if sum(g.slots for g in groups) > face.num_envs:
            return [
                evaluate_groups(face, [g], reward_fn, deterministic, self.obs_clip)[0]
                for g in groups
            ]
        return evaluate_groups(face, groups, reward_fn, deterministic, self.obs_clip)

    @override
    def close(self) -> None:
        """Nothing to release: the environments belong to the run."""
