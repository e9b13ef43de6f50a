"""The head's side of executors whose workers each step a shard of the simulations.

:class:`ShardedExecutor` cuts the work into shards (:func:`~qdil.executors.shards.shard_bounds`),
sends each worker a call, and assembles the shards' steps into the tensors the local path
returns; a subclass supplies the transport (:class:`~qdil.executors.ray.RayExecutor`).
What it computes on the head besides: the statistics' application of
:func:`~qdil.rl.collect.finish_rollout`, the learned rewards of evaluation episodes
(``reward_fn``), and the advance of the noise generator past the draws the workers replayed.
"""

from __future__ import annotations

import abc
import warnings
from dataclasses import fields
from typing import Any

import numpy as np
import torch
from typing_extensions import override

from qdil.data import Rollout
from qdil.devices import DEVICE_BACKENDS
from qdil.envs.vector import LocomotionVectorEnv
from qdil.executors.base import Executor
from qdil.executors.shards import advance, payload_bytes, shard_bounds
from qdil.executors.worker import CollectCall, EvaluateCall, Phase
from qdil.rl.collect import EpisodeLog, PolicyData, RewardFn, RolloutSteps, finish_rollout
from qdil.rl.episodes import Evaluation, Played, score
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd


class ShardedExecutor(Executor):
    """Rollouts and evaluations on workers that each own a contiguous shard of simulations.

    Args:
        num_workers: workers W; the training simulations are cut into W shards, each
            evaluation's slots into at most W.
        threads_per_worker: physics and torch threads of each worker.

    Attributes:
        bytes_sent: tensor and array bytes of the calls, counted once per receiving worker.
        bytes_received: tensor and array bytes of the workers' results.
    """

    def __init__(self, num_workers: int = 2, threads_per_worker: int = 1) -> None:
        if num_workers < 1 or threads_per_worker < 1:
            raise ValueError(
                "executor num_workers and threads_per_worker must be at least 1, got "
                f"{num_workers} and {threads_per_worker}"
            )
        self.num_workers, self.threads_per_worker = num_workers, threads_per_worker
        self.bytes_sent = self.bytes_received = 0
        self._phase = Phase(0, 0)
        self._history: list[Any] = []
        self._evaluations = 0
        self.episodes = EpisodeLog()

    # ------------------------------------------------------------ the transport
    @abc.abstractmethod
    def _launch(self, factory: Any, bounds: list[tuple[int, int]]) -> None:
        """Start one worker per training shard: ``ShardWorker(factory, start, stop, threads)``."""

    @abc.abstractmethod
    def _share(self, value: Any) -> Any:
        """A handle of ``value`` that every worker can read (sent once, read by many)."""

    @abc.abstractmethod
    def _run(self, method: str, calls: list[tuple[int, tuple]]) -> list[Any]:
        """Call ``method(*args)`` on worker i for each ``(i, args)``; results in that order."""

    # --------------------------------------------------------------- the seam
    @override
    def setup(
        self, train_env: LocomotionVectorEnv, eval_env: LocomotionVectorEnv, obs_clip: float
    ) -> None:
        """Start the workers, one training shard each, building their own environments.

        Raises:
            ValueError: the physics runs on a device backend, whose simulations stay on
                their device (naming ``env.backend``).
        """
        if train_env.backend in DEVICE_BACKENDS:
            raise ValueError(
                f"env.backend: {train_env.backend!r} keeps its simulations on one device; "
                "workers step the C MuJoCo backend only (set env.backend: mujoco, or drop "
                "the executor section)"
            )
        self.num_envs, self.eval_capacity = train_env.num_envs, eval_env.num_envs
        self.action_dim = train_env.single_action_space.shape[0]
        self.obs_clip = obs_clip
        self.bounds = shard_bounds(train_env.num_envs, self.num_workers)
        if len(self.bounds) < self.num_workers:
            warnings.warn(
                f"executor num_workers: {self.num_workers} asked, but {train_env.num_envs} "
                f"training simulations make {len(self.bounds)} shard(s) of at least one "
                f"simulation, so {len(self.bounds)} worker(s) run; more simulations "
                "(env.num_envs) would use more",
                stacklevel=2,
            )
        self._launch(train_env.factory, self.bounds)

    @override
    def start(self, seed: int) -> None:
        """Begin a phase; workers reset their shards with the call that follows."""
        self._phase = Phase(self._phase.number + 1, seed)
        self._history = []

    @override
    def collect(
        self,
        actor: VectorizedActor,
        stats: RunningMeanStd,
        num_steps: int,
        generator: torch.Generator,
        update_stats: bool,
    ) -> tuple[Rollout, PolicyData]:
        n, num_policies = self.num_envs, actor.num_models
        if n % num_policies:
            raise ValueError(f"{n} environments cannot be split among {num_policies} policies")
        call = CollectCall(actor, stats, num_steps, generator.get_state(), self.obs_clip, n)
        handle = self._share(call)
        history = list(self._history)
        parts: list[RolloutSteps] = self._run(
            "collect", [(i, (handle, self._phase, history)) for i in range(len(self.bounds))]
        )
        self._history.append(handle)
        self.bytes_sent += payload_bytes(call) * len(self.bounds)
        self.bytes_received += payload_bytes(parts)
        advance(generator, n, self.action_dim, num_steps)

        def joined(field: str) -> torch.Tensor:  # the shards side by side, in order
            return torch.cat([getattr(p, field) for p in parts], 1)

        steps = RolloutSteps(
            {key: torch.cat([p.buffers[key] for p in parts], 1) for key in parts[0].buffers},
            joined("norm_obs"),
            joined("policy_actions"),
            joined("episode_returns"),
            joined("episode_lengths"),
        )
        self.episodes.add(steps)
        return finish_rollout(steps, num_policies, stats, self.obs_clip, update_stats)

    @override
    def pop_episode_stats(self) -> tuple[list[float], list[int]]:
        return self.episodes.pop()

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
        used = actor.num_models * episodes
        if self.eval_capacity < used:
            raise ValueError(
                f"evaluation needs {used} environments, the env has {self.eval_capacity}"
            )
        self._evaluations += 1
        record = reward_fn is not None
        state = None if deterministic else generator.get_state()
        call = EvaluateCall(
            self._evaluations, actor, stats, episodes, seed, record, state, self.obs_clip
        )
        handle = self._share(call)
        # at most one shard per worker started (a small training batch may start fewer)
        bounds = shard_bounds(used, len(self.bounds))
        shards = [(i, (handle, a, b)) for i, (a, b) in enumerate(bounds)]
        plays: list[Played] = self._run("evaluate", shards)
        num_steps = max(p.num_steps for p in plays)
        rollouts = [p.rollout for p in plays]
        short = [i for i, p in enumerate(plays) if record and p.num_steps < num_steps]
        if short:  # record every slot for as many steps as the longest episode (as local)
            more = self._run(
                "extend", [(i, (*shards[i][1], num_steps - plays[i].num_steps)) for i in short]
            )
            self.bytes_received += payload_bytes(more)
            for i, extra in zip(short, more, strict=True):
                rollouts[i] = _cat([rollouts[i], extra], 0)
        self.bytes_sent += payload_bytes(call) * len(bounds)
        self.bytes_received += payload_bytes(plays)
        if not deterministic:
            advance(generator, used, self.action_dim, num_steps)
        played = Played(
            returns=np.concatenate([p.returns for p in plays]),
            lengths=np.concatenate([p.lengths for p in plays]),
            measures=np.concatenate([p.measures for p in plays]),
            env_steps=sum(p.env_steps for p in plays),
            num_steps=num_steps,
            rollout=_cat(rollouts, 1) if record else None,
        )
        return score(played, actor.num_models, episodes, reward_fn)


def _cat(rollouts: list[Any], dim: int) -> Rollout:
    """Rollouts joined along time (0) or simulations (1)."""
    return Rollout(
        **{f.name: torch.cat([getattr(r, f.name) for r in rollouts], dim) for f in fields(Rollout)}
    )
