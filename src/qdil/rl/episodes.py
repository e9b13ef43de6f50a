"""Playing whole episodes of P policies and scoring each policy.

:func:`evaluate_policies` plays ``episodes`` episodes per policy at once, stepping only
simulations whose episode is still running (autoreset disabled), and averages their
scores. It is split in two so that an executor (:mod:`qdil.executors`) can play shards of
the slots on remote workers: :class:`EpisodePlayer` steps, :func:`score` averages.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from qdil.data import Rollout
from qdil.envs.vector import LocomotionVectorEnv
from qdil.rl.collect import ActionMap, Policy, RewardFn
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from qdil.rl.sampler import PolicySampler


@dataclass(frozen=True)
class Evaluation:
    """Scores of P policies, each averaged over its episodes.

    Attributes:
        objective: (P,) mean return under the reward function (the archive's objective).
        true_objective: (P,) mean true return of the task.
        measures: (P, k) mean episode measures.
        lengths: (P,) mean episode lengths.
        env_steps: simulated env steps.
        true_std: (P,) sample standard deviation of the true return over a policy's
            episodes (zeros with one episode).
    """

    objective: np.ndarray
    true_objective: np.ndarray
    measures: np.ndarray
    lengths: np.ndarray
    env_steps: int
    true_std: np.ndarray


@dataclass(frozen=True)
class EvaluationGroup:
    """P policies to score, each over ``episodes`` episodes (one evaluation of a QD iteration).

    Attributes:
        actor: the P policies.
        stats: their observation statistics (frozen).
        episodes: episodes per policy.
        seed: reset seed (slot i of the group: ``seed + i``).
        generator: random source of the group's action noise.
    """

    actor: VectorizedActor
    stats: RunningMeanStd
    episodes: int
    seed: int
    generator: torch.Generator

    @property
    def slots(self) -> int:
        """Simulations the group plays on: P·episodes."""
        return self.actor.num_models * self.episodes


class EpisodePlayer:
    """Plays one episode on each of the first ``used`` simulations of a ``DISABLED`` env.

    Each :meth:`step` steps the simulations whose episode still runs; finished ones sit
    out (a step after all finished only records). Episode results are kept per slot, and
    the last step's rewards and foot contacts of every slot in :attr:`last_rewards` (used,)
    and :attr:`contacts` (used, k), for a caller that follows the episodes step by step.

    Args:
        env: an environment with ``autoreset_mode=DISABLED`` and at least ``used`` slots.
        used: slots that play.
        seed: reset seed (slot i: ``seed + i``), or one seed per simulation.
        record: keep every step's transition (for a learned reward).
    """

    def __init__(
        self, env: LocomotionVectorEnv, used: int, seed: int | list[int], record: bool
    ) -> None:
        if env.num_envs < used:
            raise ValueError(f"evaluation needs {used} environments, the env has {env.num_envs}")
        self.env, self.used, self.record = env, used, record
        self.running = np.zeros(env.num_envs, dtype=bool)
        self.running[:used] = True
        obs, info = env.reset(seed=seed, options={"reset_mask": self.running.copy()})
        self.obs = torch.from_numpy(obs[:used]).float()
        self.contacts = torch.from_numpy(info["foot_contact"][:used])
        self.action_map = ActionMap(env.single_action_space.low, env.single_action_space.high)
        self.returns, self.lengths = np.zeros(used), np.zeros(used)
        self.last_rewards = np.zeros(used)
        self.measures = np.zeros((used, env.num_feet))
        self.steps: list[dict[str, torch.Tensor]] = []
        self.env_steps = 0
        self.num_steps = 0
        self._actions = np.zeros((env.num_envs, env.single_action_space.shape[0]))

    @property
    def finished(self) -> bool:
        """Whether every slot's episode has ended."""
        return not self.running.any()

    def step(self, policy: Policy) -> None:
        """One env step of the running slots, actions chosen by ``policy``."""
        env, used = self.env, self.used
        _, actions, log_probs = policy(self.obs)
        executed = self.action_map(actions)
        self._actions[:used] = executed.numpy()
        active = self.running.copy()
        next_obs, reward, terminated, truncated, info = env.step(self._actions, mask=active)
        self.env_steps += int(active.sum())
        self.last_rewards = reward[:used]  # 0 for slots that sat out
        done = (terminated | truncated)[:used]
        if done.any():
            ended = info["episode"]["_r"][:used]
            self.returns[ended] = info["episode"]["r"][:used][ended]
            self.lengths[ended] = info["episode"]["l"][:used][ended]
            self.measures[ended] = info["episode"]["measures"][:used][ended]
        next_t = torch.from_numpy(next_obs[:used]).float()
        next_contacts = torch.from_numpy(info["foot_contact"][:used])
        if self.record:
            self.steps.append(
                {
                    "obs": self.obs,
                    "actions": executed,
                    "contacts": self.contacts,
                    "next_obs": next_t,
                    "next_contacts": next_contacts,
                    "rewards": torch.from_numpy(reward[:used]).float(),
                    "dones": torch.from_numpy(done.astype(np.float32)),
                    "terminated": torch.from_numpy(terminated[:used].astype(np.float32)),
                    "log_probs": log_probs,
                    "valid": torch.from_numpy(active[:used].astype(np.float32)),
                    "starts": torch.full((used,), float(not self.steps)),
                }
            )
        self.running[:used] &= ~done
        self.obs, self.contacts = next_t, next_contacts
        self.num_steps += 1

    def rollout(self, first: int = 0) -> Rollout | None:
        """The recorded steps from step ``first`` on, (T, used, ...) (``None``: not recorded)."""
        if not self.record:
            return None
        steps = self.steps[first:]
        return Rollout(**{key: torch.stack([s[key] for s in steps]) for key in steps[0]})


def score(
    returns: np.ndarray,
    lengths: np.ndarray,
    measures: np.ndarray,
    env_steps: int,
    rollout: Rollout | None,
    num_policies: int,
    episodes: int,
    reward_fn: RewardFn | None,
) -> Evaluation:
    """Per-policy means of played episodes, P·episodes slots, ``episodes`` per policy.

    Args:
        returns: (P·episodes,) true returns.
        lengths: (P·episodes,) episode lengths.
        measures: (P·episodes, k) episode measures.
        env_steps: simulated env steps.
        rollout: the recorded (T, P·episodes) steps (needed with ``reward_fn``).
        num_policies: P.
        episodes: episodes per policy.
        reward_fn: scores the episodes for the objective; ``None`` means the true return.
    """
    objective = returns
    if reward_fn is not None:
        assert rollout is not None
        objective = (reward_fn(rollout) * rollout.valid).sum(0).double().numpy()

    def per_policy(x: np.ndarray) -> np.ndarray:
        return x.reshape(num_policies, episodes, *x.shape[1:]).mean(axis=1)

    by_policy = returns.reshape(num_policies, episodes)
    return Evaluation(
        objective=per_policy(objective),
        true_objective=per_policy(returns),
        measures=per_policy(measures),
        lengths=per_policy(lengths),
        env_steps=env_steps,
        true_std=by_policy.std(axis=1, ddof=1) if episodes > 1 else np.zeros(num_policies),
    )


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
    record = reward_fn is not None
    player = EpisodePlayer(env, actor.num_models * episodes, seed, record)
    sampler = PolicySampler(actor, stats, obs_clip)

    def policy(obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        return sampler.sample(obs, generator, deterministic, log_probs=record)

    while not player.finished:
        player.step(policy)
    return score(
        player.returns,
        player.lengths,
        player.measures,
        player.env_steps,
        player.rollout(),
        actor.num_models,
        episodes,
        reward_fn,
    )
