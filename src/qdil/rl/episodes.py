"""Playing whole episodes of P policies and scoring each policy.

:func:`evaluate_groups` plays ``episodes`` episodes per policy of one or more groups at once
through a torch face (:class:`~qdil.envs.torch_step.TorchFace`, autoreset disabled),
stepping only simulations whose episode is still running, and averages each group's scores.
It is split in two so that an executor (:mod:`qdil.executors`) can play shards of the slots
on remote workers: :class:`EpisodePlayer` steps, :func:`score` averages.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from qdil.data import Rollout
from qdil.envs.torch_step import TorchFace
from qdil.rl.collect import ActionMap, Policy, RewardFn
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from qdil.rl.sampler import PolicySampler

ALL = slice(None)
"""Every slot."""


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
        generator: random source of the group's action noise (``None``: deterministic
            actions only).
    """

    actor: VectorizedActor
    stats: RunningMeanStd
    episodes: int
    seed: int
    generator: torch.Generator | None

    @property
    def slots(self) -> int:
        """Simulations the group plays on: P·episodes."""
        return self.actor.num_models * self.episodes


@dataclass(frozen=True)
class Played:
    """Played episodes of a range of slots: per-slot results and, if recorded, the steps.

    Attributes:
        returns: (n,) float64 true returns.
        lengths: (n,) float64 episode lengths.
        measures: (n, k) float64 episode measures.
        env_steps: simulated env steps.
        num_steps: steps the slots took, up to the end of their longest episode.
        rollout: (num_steps, n, ...) recorded steps (``None`` unless recorded).
    """

    returns: np.ndarray
    lengths: np.ndarray
    measures: np.ndarray
    env_steps: int
    num_steps: int
    rollout: Rollout | None


class EpisodePlayer:
    """Plays one episode on each of the first ``used`` slots of a ``DISABLED`` torch face.

    Each :meth:`step` steps the slots whose episode still runs; finished ones sit out (a
    step after all finished only records) and keep their episode's statistics in the face
    (:attr:`returns`, :attr:`lengths`, :attr:`measures`). The last step's rewards and foot
    contacts of every slot are in :attr:`last_rewards` (used,) and :attr:`contacts`
    (used, k), for a caller that follows the episodes step by step. Nothing is read on the
    host but :attr:`finished`.

    Args:
        env: a torch face with autoreset disabled and at least ``used`` slots.
        used: slots that play.
        seed: reset seed (slot i: ``seed + i``), or one seed per slot that plays.
        record: keep every step's transition (for a learned reward).
    """

    def __init__(self, env: TorchFace, used: int, seed: int | list[int], record: bool) -> None:
        if env.num_envs < used:
            raise ValueError(f"evaluation needs {used} environments, the env has {env.num_envs}")
        self.env, self.used, self.record = env, used, record
        n = env.num_envs
        first = np.zeros(n, dtype=bool)
        first[:used] = True
        if not isinstance(seed, int):  # the slots that do not play keep no seed
            seed = [*seed, *[None] * (n - len(seed))]
        obs, contacts = env.reset(seed, mask=first)
        self.running = torch.from_numpy(first).to(env.device)
        self.obs = obs[:used].float()
        self.action_map = ActionMap(env.action_low, env.action_high, env.device)
        # the last step's (N,) rewards and (N, k) contacts, cut to ``used`` when read
        self._rewards = torch.zeros(n, dtype=torch.float64, device=env.device)
        self._contacts = contacts
        self._actions = torch.zeros((n, len(env.action_low)), device=env.device)
        self.steps: list[dict[str, torch.Tensor]] = []
        self.active: list[torch.Tensor] = []  # (N,) bool per step: the slots it advanced
        self.num_steps = 0
        self._simulated = n  # slots the face simulates (narrowed to the running ones)

    @property
    def finished(self) -> bool:
        """Whether every slot's episode has ended (a read on the host)."""
        return not bool(self.running.any())

    def still_running(self) -> bool:
        """Whether any slot's episode runs (a read on the host), narrowing the face.

        Once at most half of the slots the face simulates still run, the face is told to
        simulate those alone (:meth:`TorchFace.narrow`): on a device the ended episodes
        stop costing physics, and nothing else changes.
        """
        running = int(self.running.sum())
        if 0 < running <= self._simulated // 2:
            self.env.narrow(self.running)
            self._simulated = running
        return running > 0

    @property
    def last_rewards(self) -> torch.Tensor:
        """(used,) float64 true rewards of the last step (0 for slots that sat out)."""
        return self._rewards[: self.used]

    @property
    def contacts(self) -> torch.Tensor:
        """(used, k) float32 foot contacts of the slots' current states."""
        return self._contacts[: self.used]

    @property
    def returns(self) -> torch.Tensor:
        """(used,) float64 true returns of the episodes (so far, while they run)."""
        return self.env.episode_statistics()[0][: self.used]

    @property
    def lengths(self) -> torch.Tensor:
        """(used,) int64 lengths of the episodes."""
        return self.env.episode_statistics()[1][: self.used]

    @property
    def measures(self) -> torch.Tensor:
        """(used, k) float64 measures of the episodes."""
        return self.env.episode_statistics()[2][: self.used]

    def step(self, policy: Policy) -> None:
        """One env step of the running slots, actions chosen by ``policy``."""
        used = self.used
        _, actions, log_probs = policy(self.obs)
        executed = all_actions = self.action_map(actions)
        if used < self.env.num_envs:  # the slots that do not play sit out with zero actions
            self._actions[:used] = executed
            all_actions = self._actions
        active = self.running
        step = self.env.step(all_actions, active)
        done = step.done
        self.running = active ^ done  # an episode ends only where its slot stepped
        self.active.append(active)
        next_obs = (step.obs if used == self.env.num_envs else step.obs[:used]).float()
        if self.record:
            self.steps.append(
                {
                    "obs": self.obs,
                    "actions": executed,
                    "contacts": self.contacts,
                    "next_obs": next_obs,
                    "next_contacts": step.contacts[:used],
                    "rewards": step.reward[:used].float(),
                    "dones": done[:used].float(),
                    "terminated": step.terminated[:used].float(),
                    "log_probs": log_probs,
                    "valid": active[:used].float(),
                    "starts": torch.full((used,), float(not self.steps), device=executed.device),
                }
            )
        self.obs, self._contacts, self._rewards = next_obs, step.contacts, step.reward
        self.num_steps += 1

    def rollout(self, first: int = 0, stop: int | None = None, rows: slice = ALL) -> Rollout | None:
        """Recorded steps ``first:stop`` of slots ``rows``, (T, n, ...) (``None``: not recorded)."""
        if not self.record:
            return None
        steps = self.steps[first:stop]
        # a copy of the columns, laid out as if they had been recorded alone
        return Rollout(
            **{key: torch.stack([s[key] for s in steps])[:, rows].contiguous() for key in steps[0]}
        )

    def played(self, rows: slice = ALL) -> Played:
        """The episodes of slots ``rows``, up to the end of their longest one (host arrays)."""
        counts = torch.stack(self.active)[:, : self.used][:, rows].sum(1).cpu().numpy()
        num_steps = int(np.flatnonzero(counts)[-1]) + 1
        returns, lengths, measures = (x[: self.used][rows] for x in self.env.episode_statistics())
        return Played(
            returns=returns.cpu().numpy(),
            lengths=lengths.double().cpu().numpy(),
            measures=measures.cpu().numpy(),
            env_steps=int(counts.sum()),
            num_steps=num_steps,
            rollout=self.rollout(0, num_steps, rows),
        )


def score(
    played: Played, num_policies: int, episodes: int, reward_fn: RewardFn | None
) -> Evaluation:
    """Per-policy means of played episodes, P·episodes slots, ``episodes`` per policy.

    Args:
        played: the episodes of the P·episodes slots (recorded, with ``reward_fn``).
        num_policies: P.
        episodes: episodes per policy.
        reward_fn: scores the episodes for the objective; ``None`` means the true return.
    """
    returns, rollout = played.returns, played.rollout
    objective = returns
    if reward_fn is not None:
        assert rollout is not None
        objective = (reward_fn(rollout) * rollout.valid).sum(0).double().cpu().numpy()

    def per_policy(x: np.ndarray) -> np.ndarray:
        return x.reshape(num_policies, episodes, *x.shape[1:]).mean(axis=1)

    by_policy = returns.reshape(num_policies, episodes)
    return Evaluation(
        objective=per_policy(objective),
        true_objective=per_policy(returns),
        measures=per_policy(played.measures),
        lengths=per_policy(played.lengths),
        env_steps=played.env_steps,
        true_std=by_policy.std(axis=1, ddof=1) if episodes > 1 else np.zeros(num_policies),
    )


def evaluate_groups(
    env: TorchFace,
    groups: list[EvaluationGroup],
    reward_fn: RewardFn | None = None,
    deterministic: bool = False,
    obs_clip: float = 10.0,
    sync_every: int | None = None,
) -> list[Evaluation]:
    """Play the episodes of one or more groups side by side in one batch, and score them.

    Group g takes the next ``g.slots`` simulations; its slot i resets from seed
    ``g.seed + i`` and its policies act with ``g.generator``'s noise, so each result is
    bit for bit the group's own evaluation (``tests/rl/test_collect_device.py``) while the
    batch takes as many steps in sequence as its longest episode.

    Args:
        env: a torch face with autoreset disabled and at least as many slots as the groups.
        groups: the groups, their policies and statistics on the face's device.
        reward_fn: scores the episodes for the objective (each group's apart); ``None``
            means the true return.
        deterministic: act with the mean action (re-evaluation) or sample (branch scoring).
        obs_clip: bound of normalised observations.
        sync_every: steps between two looks from the host at whether any episode runs
            (``None``: the face's). The steps after the last episode ended change nothing
            but the noise drawn: every simulation sits out of them.

    Returns:
        Per-policy means of each group, numpy arrays on the host.
    """
    record = reward_fn is not None
    bounds, start = [], 0
    for group in groups:
        bounds.append(slice(start, start + group.slots))
        start += group.slots
    seeds = [group.seed + i for group in groups for i in range(group.slots)]
    player = EpisodePlayer(env, start, groups[0].seed if len(groups) == 1 else seeds, record)
    samplers = [PolicySampler(group.actor, group.stats, obs_clip) for group in groups]

    def policy(obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        if len(groups) == 1:
            return samplers[0].sample(obs, groups[0].generator, deterministic, log_probs=record)
        outputs = [
            sampler.sample(obs[rows], group.generator, deterministic, log_probs=record)
            for sampler, group, rows in zip(samplers, groups, bounds, strict=True)
        ]
        norm, actions, log_probs = zip(*outputs, strict=True)
        joined = torch.cat(log_probs) if record else None  # type: ignore[arg-type]
        return torch.cat(norm), torch.cat(actions), joined

    every = env.sync_every if sync_every is None else sync_every
    while player.num_steps % every or player.still_running():
        player.step(policy)
    return [
        score(player.played(rows), group.actor.num_models, group.episodes, reward_fn)
        for group, rows in zip(groups, bounds, strict=True)
    ]


def evaluate_policies(
    env: TorchFace,
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
        env: a torch face with autoreset disabled and at least P·episodes slots.
        actor: P policies on the face's device.
        stats: their observation statistics there (frozen).
        episodes: episodes per policy.
        seed: reset seed.
        reward_fn: scores the episodes for the objective; ``None`` means the true return.
        deterministic: act with the mean action (re-evaluation) or sample (branch scoring).
        obs_clip: bound of normalised observations.
        generator: random source of the action noise (``None``: deterministic only).

    Returns:
        Per-policy means.
    """
    group = EvaluationGroup(actor, stats, episodes, seed, generator)
    return evaluate_groups(env, [group], reward_fn, deterministic, obs_clip)[0]
