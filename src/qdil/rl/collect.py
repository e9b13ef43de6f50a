"""Rolling out P policies at once over one batch of simulations.

Environment slot e is served by policy ``e // (N / P)``: the N simulations are cut into P
contiguous blocks. :class:`Collector` gathers fixed-length training rollouts (episodes run
on across calls, autoreset within the step); :func:`evaluate_policies` plays whole
episodes and scores each policy, stepping only simulations whose episode is still running.

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

    def start(self, seed: int) -> None:
        """Reset every simulation (the start of a VPPO phase)."""
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
        if self._obs is None or self._contacts is None:
            raise RuntimeError("call start() before collect()")
        env, n = self.env, self.env.num_envs
        if n % actor.num_models:
            raise ValueError(f"{n} environments cannot be split among {actor.num_models} policies")
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
        sampler = PolicySampler(actor, stats, self.obs_clip)
        buf["obs"][0] = self._obs
        buf["contacts"][0] = self._contacts
        buf["starts"][0] = self._starts
        for t in range(num_steps):
            # the policies read s_t from the buffer it is stored in
            norm, actions, log_probs = sampler.sample(buf["obs"][t], generator)
            executed = self.action_map(actions)
            next_obs, reward, terminated, truncated, info = env.step(executed.numpy())
            done = terminated | truncated
            contacts = info["foot_contact"]
            arr["next_obs"][t] = next_obs
            arr["next_contacts"][t] = contacts
            if done.any():  # s_{t+1} is the final state, not the reset one
                arr["next_obs"][t, done] = info["final_obs"][done]
                arr["next_contacts"][t, done] = info["final_info"]["foot_contact"][done]
                ended = info["episode"]["_r"]
                self.episode_returns += info["episode"]["r"][ended].tolist()
                self.episode_lengths += info["episode"]["l"][ended].tolist()
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
        rollout = Rollout(**buf, valid=torch.ones(shape))
        num_policies = actor.num_models
        next_by_policy = policy_blocks(buf["next_obs"].transpose(0, 1), num_policies).flatten(1, 2)
        norm_next = stats.normalize(next_by_policy, clip=self.obs_clip)
        norm_next = norm_next.reshape(n, num_steps, obs_dim).transpose(0, 1)
        if update_stats:
            stats.update(policy_blocks(buf["obs"].transpose(0, 1), num_policies).flatten(1, 2))
        return rollout, PolicyData(norm_obs, norm_next, policy_actions, buf["log_probs"])

    def pop_episode_stats(self) -> tuple[list[float], list[int]]:
        """Returns and lengths of the episodes finished since the last call."""
        stats = (self.episode_returns, self.episode_lengths)
        self.episode_returns, self.episode_lengths = [], []
        return stats


@dataclass(frozen=True)
class Evaluation:
    """Scores of P policies, each averaged over its episodes.

    Attributes:
        objective: (P,) mean return under the reward function (the archive's objective).
        true_objective: (P,) mean true return of the task.
        measures: (P, k) mean episode measures.
        lengths: (P,) mean episode lengths.
        env_steps: simulated env steps.
    """

    objective: np.ndarray
    true_objective: np.ndarray
    measures: np.ndarray
    lengths: np.ndarray
    env_steps: int


def evaluate_policies(
    env: LocomotionVectorEnv,
    actor: VectorizedActor,
    stats: RunningMeanStd,
    episodes: int,
    seed: int,
    reward_fn: RewardFn | None = None,
    deterministic: bool = False,
    obs_clip: float = 10.0,
    generator: torch.Generator | None = None,
) -> Evaluation:
    """Play ``episodes`` whole episodes per policy and average their scores.

    Args:
        env: an environment with ``autoreset_mode=DISABLED`` and at least P·episodes slots.
        actor: P policies.
        stats: their observation statistics (frozen).
        episodes: episodes per policy.
        seed: reset seed.
        reward_fn: scores the episodes for the objective; ``None`` means the true return.
        deterministic: act with the mean action (re-evaluation) or sample (branch scoring).
        obs_clip: bound of normalised observations.
        generator: random source of the action noise.

    Returns:
        Per-policy means.
    """
    num_policies = actor.num_models
    used = num_policies * episodes
    if env.num_envs < used:
        raise ValueError(f"evaluation needs {used} environments, the env has {env.num_envs}")
    running = np.zeros(env.num_envs, dtype=bool)
    running[:used] = True
    obs, info = env.reset(seed=seed, options={"reset_mask": running.copy()})
    obs_t = torch.from_numpy(obs[:used]).float()
    contacts = torch.from_numpy(info["foot_contact"][:used])
    action_map = ActionMap(env.single_action_space.low, env.single_action_space.high)
    returns, lengths = np.zeros(used), np.zeros(used)
    measures = np.zeros((used, env.num_feet))
    record = reward_fn is not None
    steps: list[dict[str, torch.Tensor]] = []
    env_steps = 0
    actions_full = np.zeros((env.num_envs, env.single_action_space.shape[0]))
    sampler = PolicySampler(actor, stats, obs_clip)
    while running.any():
        _, actions, log_probs = sampler.sample(obs_t, generator, deterministic, log_probs=record)
        executed = action_map(actions)
        actions_full[:used] = executed.numpy()
        active = running.copy()
        next_obs, reward, terminated, truncated, info = env.step(actions_full, mask=active)
        env_steps += int(active.sum())
        done = (terminated | truncated)[:used]
        if done.any():
            ended = info["episode"]["_r"][:used]
            returns[ended] = info["episode"]["r"][:used][ended]
            lengths[ended] = info["episode"]["l"][:used][ended]
            measures[ended] = info["episode"]["measures"][:used][ended]
        next_t = torch.from_numpy(next_obs[:used]).float()
        next_contacts = torch.from_numpy(info["foot_contact"][:used])
        if record:
            steps.append(
                {
                    "obs": obs_t,
                    "actions": executed,
                    "contacts": contacts,
                    "next_obs": next_t,
                    "next_contacts": next_contacts,
                    "rewards": torch.from_numpy(reward[:used]).float(),
                    "dones": torch.from_numpy(done.astype(np.float32)),
                    "terminated": torch.from_numpy(terminated[:used].astype(np.float32)),
                    "log_probs": log_probs,
                    "valid": torch.from_numpy(active[:used].astype(np.float32)),
                    "starts": torch.full((used,), float(not steps)),
                }
            )
        running[:used] &= ~done
        obs_t, contacts = next_t, next_contacts
    objective = returns
    if record:
        assert reward_fn is not None
        rollout = Rollout(**{key: torch.stack([s[key] for s in steps]) for key in steps[0]})
        objective = (reward_fn(rollout) * rollout.valid).sum(0).double().numpy()

    def per_policy(x: np.ndarray) -> np.ndarray:
        return x.reshape(num_policies, episodes, *x.shape[1:]).mean(axis=1)

    return Evaluation(
        objective=per_policy(objective),
        true_objective=per_policy(returns),
        measures=per_policy(measures),
        lengths=per_policy(lengths),
        env_steps=env_steps,
    )
