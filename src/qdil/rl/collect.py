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
from qdil.envs.vector import LocomotionVectorEnv
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
        self, low: np.ndarray, high: np.ndarray, device: torch.device | str | None = None
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
    """Collects fixed-length rollouts from a ``SAME_STEP`` autoreset environment.

    Args:
        env: the training environment (``autoreset_mode=SAME_STEP``).
        obs_clip: bound of normalised observations.
    """

    def __init__(self, env: LocomotionVectorEnv, obs_clip: float = 10.0) -> None:
        if env.autoreset_mode.value != "SameStep":
            raise ValueError("the training environment must use autoreset_mode=SAME_STEP")
        self.env = env
        self.obs_clip = obs_clip
        self.action_map = ActionMap(env.single_action_space.low, env.single_action_space.high)
        self.episode_returns: list[float] = []
        self.episode_lengths: list[int] = []
        self._obs: torch.Tensor | None = None
        self._contacts: torch.Tensor | None = None
        self._starts: torch.Tensor | None = None

    def start(self, seed: int | list[int]) -> None:
        """Reset every simulation (the start of a VPPO phase).

        Args:
            seed: simulation i is seeded with ``seed + i``; a list gives one seed each (a
                shard of a larger batch passes the seeds of its simulations).
        """
        obs, info = self.env.reset(seed=seed)
        self._obs = torch.from_numpy(obs).float()
        self._contacts = torch.from_numpy(info["foot_contact"])
        self._starts = torch.ones(len(obs))

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
            actor: P policies; N must be divisible by P.
            stats: their observation statistics (used frozen during the rollout).
            num_steps: T.
            generator: random source of the action noise.
            update_stats: merge the rollout's observations into ``stats`` afterwards.

        Returns:
            The rollout (raw observations, executed actions, true rewards) and PPO's extras.
        """
        n = self.env.num_envs
        if n % actor.num_models:
            raise ValueError(f"{n} environments cannot be split among {actor.num_models} policies")
        sampler = PolicySampler(actor, stats, self.obs_clip)
        steps = self.roll(lambda obs: sampler.sample(obs, generator), num_steps)
        for _, _, returns, lengths in steps.ended:
            self.episode_returns += returns.tolist()
            self.episode_lengths += lengths.tolist()
        return finish_rollout(steps, actor.num_models, stats, self.obs_clip, update_stats)

    def roll(self, policy: Policy, num_steps: int) -> RolloutSteps:
        """Step the simulations ``num_steps`` times with ``policy`` choosing the actions.

        Args:
            policy: maps the (n, obs_dim) observations of a step to the policies' outputs.
            num_steps: T.

        Returns:
            The step buffers; episodes run on into the next call.
        """
        if self._obs is None or self._contacts is None or self._starts is None:
            raise RuntimeError("call start() before collect()")
        env, n = self.env, self.env.num_envs
        obs_dim, k = self._obs.shape[1], self._contacts.shape[1]
        action_dim = env.single_action_space.shape[0]
        shape = (num_steps, n)
        buf = {
            "obs": torch.zeros((*shape, obs_dim)),
            "next_obs": torch.zeros((*shape, obs_dim)),
            "actions": torch.zeros((*shape, action_dim)),
            "contacts": torch.zeros((*shape, k)),
            "next_contacts": torch.zeros((*shape, k)),
            "rewards": torch.zeros(shape),
            "dones": torch.zeros(shape),
            "terminated": torch.zeros(shape),
            "log_probs": torch.zeros(shape),
            "starts": torch.zeros(shape),
        }
        # numpy views of the buffers: the loop writes the env's arrays into them directly
        # (the same float64 -> float32 rounding as a tensor copy), without tensor wrappers
        arr = {key: value.numpy() for key, value in buf.items()}
        norm_obs = torch.zeros((*shape, obs_dim))
        policy_actions = torch.zeros((*shape, action_dim))
        ended: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []
        buf["obs"][0] = self._obs
        buf["contacts"][0] = self._contacts
        buf["starts"][0] = self._starts
        for t in range(num_steps):
            # the policies read s_t from the buffer it is stored in
            norm, actions, log_probs = policy(buf["obs"][t])
            executed = self.action_map(actions)
            next_obs, reward, terminated, truncated, info = env.step(executed.numpy())
            done = terminated | truncated
            contacts = info["foot_contact"]
            arr["next_obs"][t] = next_obs
            arr["next_contacts"][t] = contacts
            if done.any():  # s_{t+1} is the final state, not the reset one
                arr["next_obs"][t, done] = info["final_obs"][done]
                arr["next_contacts"][t, done] = info["final_info"]["foot_contact"][done]
                mask = info["episode"]["_r"]
                episode = info["episode"]
                ended.append((t, np.flatnonzero(mask), episode["r"][mask], episode["l"][mask]))
            buf["actions"][t] = executed
            arr["rewards"][t] = reward
            arr["dones"][t] = done
            arr["terminated"][t] = terminated
            buf["log_probs"][t] = log_probs
            norm_obs[t] = norm
            policy_actions[t] = actions
            if t + 1 < num_steps:
                arr["obs"][t + 1] = next_obs
                arr["contacts"][t + 1] = contacts
                arr["starts"][t + 1] = done
        # where the next call goes on
        self._obs = torch.from_numpy(next_obs).float()
        self._contacts = torch.from_numpy(contacts)
        self._starts = torch.from_numpy(done.astype(np.float32))
        return RolloutSteps(buf, norm_obs, policy_actions, ended)

    def pop_episode_stats(self) -> tuple[list[float], list[int]]:
        """Returns and lengths of the episodes finished since the last call."""
        stats = (self.episode_returns, self.episode_lengths)
        self.episode_returns, self.episode_lengths = [], []
        return stats


@dataclass(frozen=True)
class RolloutSteps:
    """What :meth:`Collector.roll` records, before the statistics are applied.

    Attributes:
        buffers: the :class:`Rollout` fields except ``valid``, (T, n, ...) tensors.
        norm_obs: (T, n, obs_dim) normalised s_t as the policies saw them.
        policy_actions: (T, n, A) sampled, unclipped actions.
        ended: per step where episodes ended: (t, (e,) simulation indices, (e,) returns,
            (e,) lengths), indices in simulation order.
    """

    buffers: dict[str, torch.Tensor]
    norm_obs: torch.Tensor
    policy_actions: torch.Tensor
    ended: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]


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
    rollout = Rollout(**buf, valid=torch.ones((num_steps, n)))
    next_by_policy = policy_blocks(buf["next_obs"].transpose(0, 1), num_policies).flatten(1, 2)
    norm_next = stats.normalize(next_by_policy, clip=obs_clip)
    norm_next = norm_next.reshape(n, num_steps, obs_dim).transpose(0, 1)
    if update_stats:
        stats.update(policy_blocks(buf["obs"].transpose(0, 1), num_policies).flatten(1, 2))
    pdata = PolicyData(steps.norm_obs, norm_next, steps.policy_actions, buf["log_probs"])
    return rollout, pdata
