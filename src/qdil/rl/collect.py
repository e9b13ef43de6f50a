"""Rolling out P policies at once over one batch of simulations.

Environment slot e is served by policy ``e // (N / P)``: the N simulations are cut into P
contiguous blocks. :class:`Collector` gathers fixed-length training rollouts (episodes run
on across calls, autoreset within the step); :mod:`qdil.rl.episodes` plays whole episodes.

A rollout is split in two so that an executor (:mod:`qdil.executors`) can run the stepping
part on remote workers, each on a contiguous shard of the simulations, and assemble the
same tensors on the head: :meth:`Collector.roll` steps, :func:`finish_rollout` applies the
policies' statistics.

Policies act in [-1, 1]^A: a sampled action is clipped there and mapped linearly to the
task's action bounds, and PPO keeps the unclipped sample for its likelihood ratios.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from qdil.data import Rollout
from qdil.envs.torch_step import TorchFace
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from qdil.rl.sampler import PolicySampler

RewardFn = Callable[[Rollout], torch.Tensor]
"""Maps a rollout to (T, N) per-step rewards."""

Policy = Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]]
"""(n, obs_dim) raw observations -> normalised ones, (n, A) unclipped actions, (n,) log-probs."""


class ActionMap:
    """Clip policy actions to [-1, 1] and map them to the task's action bounds.

    Args:
        low: (A,) lower action bounds.
        high: (A,) upper action bounds.
        device: where the actions are (the run's device).
    """

    def __init__(
        self, low: np.ndarray, high: np.ndarray, device: torch.device | None = None
    ) -> None:
        self.low = torch.as_tensor(low, dtype=torch.float32, device=device)
        self.half = torch.as_tensor((high - low) / 2.0, dtype=torch.float32, device=device)

    def __call__(self, actions: torch.Tensor) -> torch.Tensor:
        """(..., A) policy actions -> (..., A) executed actions."""
        return self.low + (actions.clamp(-1.0, 1.0) + 1.0) * self.half


@dataclass(frozen=True)
class PolicyData:
    """What PPO needs beside the rollout, per step: (T, N, ...) tensors.

    Attributes:
        norm_obs: normalised s_t as the policy saw it.
        norm_next_obs: normalised s_{t+1} (the final observation at an episode end).
        actions: the sampled, unclipped policy actions.
        log_probs: their log-likelihoods under the acting policy.
    """

    norm_obs: torch.Tensor
    norm_next_obs: torch.Tensor
    actions: torch.Tensor
    log_probs: torch.Tensor


def policy_blocks(x: torch.Tensor, num_policies: int) -> torch.Tensor:
    """(N, ...) -> (P, N/P, ...): environment slot e belongs to policy e // (N/P)."""
    return x.reshape(num_policies, x.shape[0] // num_policies, *x.shape[1:])


class Collector:
    """Collects fixed-length rollouts through a ``SAME_STEP`` autoreset torch face.

    The rollout stays on the face's device: no step reads from it on the host (the finished
    episodes' returns and lengths are read once, in :meth:`pop_episode_stats`).

    Args:
        env: the torch face of the training environment (``autoreset_mode=SAME_STEP``).
        obs_clip: bound of normalised observations.
    """

    def __init__(self, env: TorchFace, obs_clip: float = 10.0) -> None:
        if not env.autoreset:
            raise ValueError("the training environment must use autoreset_mode=SAME_STEP")
        self.env = env
        self.device = env.device
        self.obs_clip = obs_clip
        self.action_map = ActionMap(env.action_low, env.action_high, self.device)
        self.episodes = EpisodeLog()
        self._obs: torch.Tensor | None = None
        self._contacts: torch.Tensor | None = None
        self._starts: torch.Tensor | None = None

    def start(self, seed: int | list[int]) -> None:
        """Reset every simulation (the start of a VPPO phase).

        Args:
            seed: simulation i is seeded with ``seed + i``; a list gives one seed each (a
                shard of a larger batch passes the seeds of its simulations).
        """
        obs, contacts = self.env.reset(seed)
        self._obs, self._contacts = obs.float(), contacts
        self._starts = torch.ones(len(obs), device=self.device)

    def collect(
        self,
        actor: VectorizedActor,
        stats: RunningMeanStd,
        num_steps: int,
        generator: torch.Generator,
        update_stats: bool,
    ) -> tuple[Rollout, PolicyData]:
        """Roll out ``num_steps`` steps of P policies on the N simulations.

        Args:
            actor: P policies on the face's device; N must be divisible by P.
            stats: their observation statistics there (used frozen during the rollout).
            num_steps: T.
            generator: random source of the action noise, on the face's device.
            update_stats: merge the rollout's observations into ``stats`` afterwards.

        Returns:
            The rollout (raw observations, executed actions, true rewards) and PPO's extras,
            (T, N, ...) tensors on the face's device.
        """
        n = self.env.num_envs
        if n % actor.num_models:
            raise ValueError(f"{n} environments cannot be split among {actor.num_models} policies")
        sampler = PolicySampler(actor, stats, self.obs_clip)
        steps = self.roll(lambda obs: sampler.sample(obs, generator), num_steps)
        self.episodes.add(steps)
        return finish_rollout(steps, actor.num_models, stats, self.obs_clip, update_stats)

    def roll(self, policy: Policy, num_steps: int) -> RolloutSteps:
        """Step the simulations ``num_steps`` times with ``policy`` choosing the actions.

        Args:
            policy: maps the (n, obs_dim) observations of a step to the policies' outputs.
            num_steps: T.

        Returns:
            The steps; episodes run on into the next call.
        """
        if self._obs is None or self._contacts is None or self._starts is None:
            raise RuntimeError("call start() before collect()")
        obs, contacts = self._obs, self._contacts
        # each step's tensors are new: kept (float32 observations, not the float64 ones) and
        # stacked once, which costs less than writing each into a (T, N) buffer
        kept: list[dict[str, torch.Tensor]] = []
        for _ in range(num_steps):
            norm, actions, log_probs = policy(obs)
            executed = self.action_map(actions)
            step = self.env.step(executed)
            next_obs = step.final_obs.float()  # s_{t+1} is the state reached, not the reset one
            kept.append({
                "obs": obs, "next_obs": next_obs, "actions": executed, "contacts": contacts,
                "next_contacts": step.final_contacts, "rewards": step.reward, "dones": step.done,
                "terminated": step.terminated, "log_probs": log_probs, "norm_obs": norm,
                "policy_actions": actions, "episode_returns": step.episode_return,
                "episode_lengths": step.episode_length,
            })  # fmt: skip
            obs = next_obs if step.obs is step.final_obs else step.obs.float()
            contacts = step.contacts
        t = {key: torch.stack([kept_step[key] for kept_step in kept]) for key in kept[0]}
        dones = t["dones"].float()
        buffers = {
            **{key: t[key] for key in ("obs", "next_obs", "actions", "contacts", "next_contacts")},
            "rewards": t["rewards"].float(),
            "dones": dones,
            "terminated": t["terminated"].float(),
            "log_probs": t["log_probs"],
            "starts": torch.cat([self._starts[None], dones[:-1]]),
        }
        # where the next call goes on
        self._obs, self._contacts, self._starts = obs, contacts, dones[-1]
        return RolloutSteps(
            buffers, t["norm_obs"], t["policy_actions"], t["episode_returns"], t["episode_lengths"]
        )

    def pop_episode_stats(self) -> tuple[list[float], list[int]]:
        """Returns and lengths of the episodes finished since the last call (one host read)."""
        return self.episodes.pop()


@dataclass(frozen=True)
class RolloutSteps:
    """What :meth:`Collector.roll` records, before the statistics are applied.

    Attributes:
        buffers: the :class:`Rollout` fields except ``valid``, (T, n, ...) tensors.
        norm_obs: (T, n, obs_dim) normalised s_t as the policies saw them.
        policy_actions: (T, n, A) sampled, unclipped actions.
        episode_returns: (T, n) float64 true returns of the episodes that ended at step t
            (0 elsewhere).
        episode_lengths: (T, n) int64 lengths of those episodes (0 elsewhere).
    """

    buffers: dict[str, torch.Tensor]
    norm_obs: torch.Tensor
    policy_actions: torch.Tensor
    episode_returns: torch.Tensor
    episode_lengths: torch.Tensor


class EpisodeLog:
    """The training episodes that ended in rollouts, read from the device only when popped."""

    def __init__(self) -> None:
        self._rollouts: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = []

    def add(self, steps: RolloutSteps) -> None:
        """Keep the episodes that ended in ``steps``."""
        ended = steps.buffers["dones"] > 0
        self._rollouts.append((ended, steps.episode_returns, steps.episode_lengths))

    def pop(self) -> tuple[list[float], list[int]]:
        """Returns and lengths of the episodes kept since the last call (step, then slot)."""
        returns: list[float] = []
        lengths: list[int] = []
        for ended, episode_returns, episode_lengths in self._rollouts:
            returns += episode_returns[ended].tolist()
            lengths += episode_lengths[ended].tolist()
        self._rollouts = []
        return returns, lengths


def finish_rollout(
    steps: RolloutSteps,
    num_policies: int,
    stats: RunningMeanStd,
    obs_clip: float,
    update_stats: bool,
) -> tuple[Rollout, PolicyData]:
    """The rollout and PPO's extras of all N simulations, P blocks of N/P.

    Args:
        steps: the recorded (T, N, ...) steps.
        num_policies: P.
        stats: the policies' observation statistics.
        obs_clip: bound of normalised observations.
        update_stats: merge the observations into ``stats``.
    """
    buf = steps.buffers
    num_steps, n, obs_dim = buf["obs"].shape
    rollout = Rollout(**buf, valid=torch.ones((num_steps, n), device=buf["obs"].device))
    next_by_policy = policy_blocks(buf["next_obs"].transpose(0, 1), num_policies).flatten(1, 2)
    norm_next = stats.normalize(next_by_policy, clip=obs_clip)
    norm_next = norm_next.reshape(n, num_steps, obs_dim).transpose(0, 1)
    if update_stats:
        stats.update(policy_blocks(buf["obs"].transpose(0, 1), num_policies).flatten(1, 2))
    pdata = PolicyData(steps.norm_obs, norm_next, steps.policy_actions, buf["log_probs"])
    return rollout, pdata
