"""A worker's side of remote execution: one shard of simulations, stepped next to its policies.

:class:`ShardWorker` is a plain class (Ray wraps it into an actor in :mod:`qdil.executors.ray`)
so that its numbers can be checked without a cluster. Every call carries what the worker
needs to compute exactly what the head's local path would: the policies, their statistics,
the noise generator's state, and the seeds. The training shard's episodes run on across the
calls of a VPPO phase; a worker that was restarted mid-phase (a killed process, a lost node)
rebuilds that state by replaying the phase's earlier calls, which the head keeps as
references, so a retried call returns what the first attempt would have.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import torch

from qdil import numerics
from qdil.data import Rollout
from qdil.envs.faces import torch_face
from qdil.envs.torch_step import TorchFace
from qdil.envs.vector import LocomotionVectorEnv
from qdil.executors.shards import NoiseReplay, ShardPolicies
from qdil.rl.collect import Collector, RolloutSteps
from qdil.rl.episodes import EpisodePlayer, Played
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd


@dataclass(frozen=True)
class Phase:
    """The start of a VPPO phase: every training simulation i reset with ``seed + i``."""

    number: int
    seed: int


@dataclass(frozen=True)
class CollectCall:
    """One training rollout of P policies on N simulations (see ``Collector.collect``)."""

    actor: VectorizedActor
    stats: RunningMeanStd
    num_steps: int
    noise_state: torch.Tensor
    obs_clip: float
    num_envs: int


@dataclass(frozen=True)
class EvaluateCall:
    """``episodes`` evaluation episodes of each of P policies (see ``evaluate_policies``)."""

    number: int
    actor: VectorizedActor
    stats: RunningMeanStd
    episodes: int
    seed: int
    record: bool
    noise_state: torch.Tensor | None
    obs_clip: float


class ShardWorker:
    """Owns the simulations [start, stop) of the training batch and evaluation shards.

    Args:
        factory: ``LocomotionVectorEnv.factory`` of the head's environments.
        start: first training simulation of the shard.
        stop: end of the training shard.
        threads: physics and torch threads of this worker.
        numerics_env: the head's :func:`qdil.numerics.worker_env`; a worker whose MKL mode
            or torch kernels differ from it raises ``RuntimeError`` instead of computing.
    """

    def __init__(
        self,
        factory: Callable[..., LocomotionVectorEnv],
        start: int,
        stop: int,
        threads: int,
        numerics_env: dict[str, str] | None = None,
    ) -> None:
        # a worker on another CPU computes with the head's kernels or refuses to start
        numerics.require_env(numerics_env or {}, f"the worker of simulations {start}-{stop}")
        torch.set_num_threads(threads)
        self.factory, self.start, self.stop, self.threads = factory, start, stop, threads
        env = factory(stop - start, autoreset_mode="SameStep", num_threads=threads)
        self.collector = Collector(torch_face(env))
        self.eval_faces: dict[int, TorchFace] = {}
        self.phase: int | None = None
        self.calls = 0
        self.player: tuple[int, EpisodePlayer, ShardPolicies, NoiseReplay | None] | None = None

    def resolve(self, history: list[Any]) -> list[CollectCall]:
        """The calls ``history`` refers to (the Ray actor fetches them from the object store)."""
        return history

    # ------------------------------------------------------------------ training
    def collect(self, call: CollectCall, phase: Phase, history: list[Any]) -> RolloutSteps:
        """The shard's part of a training rollout; ``history``: the phase's earlier calls."""
        if (self.phase, self.calls) != (phase.number, len(history)):
            # a new phase, or a restarted worker that lost its simulations' state
            self.collector.start([phase.seed + self.start + j for j in range(self.size)])
            self.phase, self.calls = phase.number, 0
            for earlier in self.resolve(history):
                self._roll(earlier)
        return self._roll(call)

    @property
    def size(self) -> int:
        """Training simulations of the shard."""
        return self.stop - self.start

    def _roll(self, call: CollectCall) -> RolloutSteps:
        block = call.num_envs // call.actor.num_models
        policies = ShardPolicies(
            call.actor, call.stats, call.obs_clip, self.start, self.stop, block
        )
        action_dim = call.actor.sizes[-1]
        noise = NoiseReplay(call.noise_state, call.num_envs, action_dim, self.start, self.stop)
        steps = self.collector.roll(
            lambda obs: policies.sample(obs, noise(), False, True), call.num_steps
        )
        self.calls += 1
        return steps

    # ---------------------------------------------------------------- evaluation
    def evaluate(self, call: EvaluateCall, start: int, stop: int) -> Played:
        """Play the slots [start, stop) of an evaluation to the end of their episodes."""
        face = self.eval_faces.get(stop - start)
        if face is None:
            env = self.factory(stop - start, autoreset_mode="Disabled", num_threads=self.threads)
            face = self.eval_faces[stop - start] = torch_face(env)
        seeds = [call.seed + start + j for j in range(stop - start)]
        player = EpisodePlayer(face, stop - start, seeds, call.record)
        policies = ShardPolicies(call.actor, call.stats, call.obs_clip, start, stop, call.episodes)
        noise = None
        if call.noise_state is not None:
            rows = call.actor.num_models * call.episodes
            noise = NoiseReplay(call.noise_state, rows, call.actor.sizes[-1], start, stop)
        self.player = (call.number, player, policies, noise)
        while player.still_running():
            self._step()
        return player.played()

    def extend(self, call: EvaluateCall, start: int, stop: int, num_steps: int) -> Rollout | None:
        """``num_steps`` more recorded steps after the shard's episodes ended.

        The head records as many steps for every slot as the longest episode of all
        shards takes (finished slots record invalid steps); a shard whose episodes ended
        earlier goes on stepping nothing, with the same policies and noise, until then.
        """
        if self.player is None or self.player[0] != call.number:  # restarted: play it again
            self.evaluate(call, start, stop)
        assert self.player is not None
        player = self.player[1]
        first = player.num_steps
        for _ in range(num_steps):
            self._step()
        return player.rollout(first)

    def _step(self) -> None:
        assert self.player is not None
        _, player, policies, noise = self.player
        deterministic = noise is None
        player.step(
            lambda obs: policies.sample(
                obs, None if noise is None else noise(), deterministic, player.record
            )
        )
