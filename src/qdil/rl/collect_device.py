"""Rollouts and evaluations whose physics, policies and buffers stay on one torch device.

The twins of :class:`~qdil.rl.collect.Collector` and
:func:`~qdil.rl.collect.evaluate_policies` for device backends (``env.backend: warp``):
they step the environment through its torch face
(:class:`~qdil.envs.torch_vector.TorchVectorEnv`), so actions, observations, rewards and
the rollout buffers never leave the device within a rollout. What goes to the host, and
when:

- a training rollout: nothing per step; the finished episodes' returns and lengths once, in
  :meth:`DeviceCollector.pop_episode_stats`, and the reset-noise queues every
  ``reset_depth`` steps (:class:`TorchVectorEnv`);
- an evaluation: whether any episode still runs, once every ``sync_every`` steps (the steps
  after the last episode ended change nothing: every simulation sits out of them), and the
  scores once at the end, as numpy arrays for pyribs.

The same seeds give the same rollouts as the numpy path on the same backend
(``tests/rl/test_collect_device.py``).
"""

from __future__ import annotations

import numpy as np
import torch

from qdil.data import Rollout
from qdil.envs.torch_vector import TorchVectorEnv
from qdil.envs.vector import LocomotionVectorEnv
from qdil.rl.collect import ActionMap, PolicyData, RewardFn, policy_blocks
from qdil.rl.episodes import Evaluation, EvaluationGroup
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from qdil.rl.sampler import PolicySampler


class DeviceCollector:
    """Collects fixed-length rollouts on the physics' device (``SAME_STEP`` autoreset).

    The same interface as :class:`~qdil.rl.collect.Collector`; rollouts and policy data
    are tensors on :attr:`device`.

    Args:
        env: the training environment, on a device backend (``autoreset_mode=SAME_STEP``).
        obs_clip: bound of normalised observations.
        reset_depth: initial states queued per simulation (see :class:`TorchVectorEnv`).
    """

    def __init__(
        self, env: LocomotionVectorEnv, obs_clip: float = 10.0, reset_depth: int = 16
    ) -> None:
        if env.autoreset_mode.value != "SameStep":
            raise ValueError("the training environment must use autoreset_mode=SAME_STEP")
        self.env = env
        self.torch_env = TorchVectorEnv(env, reset_depth)
        self.device = self.torch_env.device
        self.obs_clip = obs_clip
        space = env.single_action_space
        self.action_map = ActionMap(space.low, space.high, self.device)
        self._episodes: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = []
        self._obs: torch.Tensor | None = None
        self._contacts: torch.Tensor | None = None
        self._starts: torch.Tensor | None = None

    def start(self, seed: int) -> None:
        """Reset every simulation (the start of a VPPO phase)."""
        obs, contacts = self.torch_env.reset(seed)
        self._obs = obs.float()
        self._contacts = contacts
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
            actor: P policies on :attr:`device`; N must be divisible by P.
            stats: their observation statistics on :attr:`device` (frozen in the rollout).
            num_steps: T.
            generator: random source of the action noise, on :attr:`device`.
            update_stats: merge the rollout's observations into ``stats`` afterwards.

        Returns:
            The rollout (raw observations, executed actions, true rewards) and PPO's extras,
            (T, N, ...) tensors on :attr:`device`.
        """
        if self._obs is None or self._contacts is None or self._starts is None:
            raise RuntimeError("call start() before collect()")
        n = self.env.num_envs
        if n % actor.num_models:
            raise ValueError(f"{n} environments cannot be split among {actor.num_models} policies")
        obs_dim, k = self._obs.shape[1], self._contacts.shape[1]
        action_dim = self.env.single_action_space.shape[0]
        shape = (num_steps, n)

        def zeros(*tail: int) -> torch.Tensor:
            return torch.zeros((*shape, *tail), device=self.device)

        buf = {
            "obs": zeros(obs_dim),
            "next_obs": zeros(obs_dim),
            "actions": zeros(action_dim),
            "contacts": zeros(k),
            "next_contacts": zeros(k),
            "rewards": zeros(),
            "dones": zeros(),
            "terminated": zeros(),
            "log_probs": zeros(),
            "starts": zeros(),
        }
        norm_obs, policy_actions = zeros(obs_dim), zeros(action_dim)
        episode_returns = torch.zeros(shape, dtype=torch.float64, device=self.device)
        episode_lengths = torch.zeros(shape, dtype=torch.int64, device=self.device)
        sampler = PolicySampler(actor, stats, self.obs_clip)
        buf["obs"][0] = self._obs
        buf["contacts"][0] = self._contacts
        buf["starts"][0] = self._starts
        for t in range(num_steps):
            norm, actions, log_probs = sampler.sample(buf["obs"][t], generator)
            executed = self.action_map(actions)
            step = self.torch_env.step(executed)
            done = step.done
            # s_{t+1} is the state the step reached, not the reset one
            buf["next_obs"][t] = step.final_obs
            buf["next_contacts"][t] = step.final_contacts
            buf["actions"][t] = executed
            buf["rewards"][t] = step.reward
            buf["dones"][t] = done
            buf["terminated"][t] = step.terminated
            buf["log_probs"][t] = log_probs
            norm_obs[t] = norm
            policy_actions[t] = actions
            episode_returns[t] = step.episode_return
            episode_lengths[t] = step.episode_length
            if t + 1 < num_steps:
                buf["obs"][t + 1] = step.obs
                buf["contacts"][t + 1] = step.contacts
                buf["starts"][t + 1] = done
        # where the next call goes on
        self._obs = step.obs.float()
        self._contacts = step.contacts
        self._starts = done.float()
        self._episodes.append((buf["dones"] > 0, episode_returns, episode_lengths))
        rollout = Rollout(**buf, valid=torch.ones(shape, device=self.device))
        num_policies = actor.num_models
        next_by_policy = policy_blocks(buf["next_obs"].transpose(0, 1), num_policies)
        norm_next = stats.normalize(next_by_policy.flatten(1, 2), clip=self.obs_clip)
        norm_next = norm_next.reshape(n, num_steps, obs_dim).transpose(0, 1)
        if update_stats:
            stats.update(policy_blocks(buf["obs"].transpose(0, 1), num_policies).flatten(1, 2))
        return rollout, PolicyData(norm_obs, norm_next, policy_actions, buf["log_probs"])

    def pop_episode_stats(self) -> tuple[list[float], list[int]]:
        """Returns and lengths of the episodes finished since the last call (one sync)."""
        returns: list[float] = []
        lengths: list[int] = []
        for ended, episode_returns, episode_lengths in self._episodes:
            returns += episode_returns[ended].tolist()
            lengths += episode_lengths[ended].tolist()
        self._episodes = []
        return returns, lengths


def evaluate_on_device(
    env: TorchVectorEnv,
    actor: VectorizedActor,
    stats: RunningMeanStd,
    episodes: int,
    seed: int,
    reward_fn: RewardFn | None = None,
    deterministic: bool = False,
    obs_clip: float = 10.0,
    generator: torch.Generator | None = None,
    sync_every: int = 16,
) -> Evaluation:
    """:func:`~qdil.rl.collect.evaluate_policies` with the episodes played on the device.

    Args:
        env: the torch face of an environment with ``autoreset_mode=DISABLED`` and at least
            P·episodes slots.
        actor: P policies on the environment's device.
        stats: their observation statistics on that device (frozen).
        episodes: episodes per policy.
        seed: reset seed.
        reward_fn: scores the episodes for the objective; ``None`` means the true return.
        deterministic: act with the mean action (re-evaluation) or sample (branch scoring).
        obs_clip: bound of normalised observations.
        generator: random source of the action noise, on the device.
        sync_every: steps between two looks from the host at whether any episode runs.

    Returns:
        Per-policy means, numpy arrays on the host.
    """
    group = EvaluationGroup(actor, stats, episodes, seed, generator)  # type: ignore[arg-type]
    return evaluate_groups_on_device(env, [group], reward_fn, deterministic, obs_clip, sync_every)[
        0
    ]


class _GroupPlay:
    """The episodes of one group on its slots ``[offset, offset + slots)`` of a batch."""

    def __init__(self, group: EvaluationGroup, offset: int, env: TorchVectorEnv, obs_clip: float):
        self.group, self.rows = group, slice(offset, offset + group.slots)
        device = env.device
        self.returns = torch.zeros(group.slots, dtype=torch.float64, device=device)
        self.lengths = torch.zeros(group.slots, dtype=torch.int64, device=device)
        self.measures = torch.zeros((group.slots, env.num_feet), dtype=torch.float64, device=device)
        self.sampler = PolicySampler(group.actor, group.stats, obs_clip)
        self.steps: list[dict[str, torch.Tensor]] = []
        self.active_counts: list[torch.Tensor] = []

    def score(self, reward_fn: RewardFn | None) -> Evaluation:
        """The group's per-policy means; steps after its last episode ended are dropped."""
        group = self.group
        counts = torch.stack(self.active_counts).cpu().numpy()
        num_steps = int(np.flatnonzero(counts)[-1]) + 1
        objective = self.returns
        if reward_fn is not None:
            steps = self.steps[:num_steps]
            rollout = Rollout(**{key: torch.stack([s[key] for s in steps]) for key in steps[0]})
            objective = (reward_fn(rollout) * rollout.valid).sum(0).double()
        num_policies, episodes = group.actor.num_models, group.episodes

        def per_policy(x: torch.Tensor) -> np.ndarray:
            x = x.double().cpu().numpy()
            return x.reshape(num_policies, episodes, *x.shape[1:]).mean(axis=1)

        by_policy = self.returns.double().cpu().numpy().reshape(num_policies, episodes)
        return Evaluation(
            objective=per_policy(objective),
            true_objective=per_policy(self.returns),
            measures=per_policy(self.measures),
            lengths=per_policy(self.lengths),
            env_steps=int(counts.sum()),
            true_std=by_policy.std(axis=1, ddof=1) if episodes > 1 else np.zeros(num_policies),
        )


def evaluate_groups_on_device(
    env: TorchVectorEnv,
    groups: list[EvaluationGroup],
    reward_fn: RewardFn | None = None,
    deterministic: bool = False,
    obs_clip: float = 10.0,
    sync_every: int = 16,
) -> list[Evaluation]:
    """Play the episodes of several groups side by side, on the device, in one batch.

    Group g takes the next ``g.slots`` simulations; its slot i resets from seed
    ``g.seed + i`` and its policies act with ``g.generator``'s noise, so each result is
    bit for bit the group's own :func:`evaluate_on_device` (``tests/rl/test_collect_device.py``)
    while the batch takes as many steps in sequence as its longest episode.

    Args:
        env: the torch face of an environment with ``autoreset_mode=DISABLED`` and at least
            as many slots as the groups together.
        groups: the groups, their policies and statistics on the environment's device.
        reward_fn: scores the episodes for the objective (each group's apart); ``None``
            means the true return.
        deterministic: act with the mean action (re-evaluation) or sample (branch scoring).
        obs_clip: bound of normalised observations.
        sync_every: steps between two looks from the host at whether any episode runs.

    Returns:
        Per-policy means of each group, numpy arrays on the host.
    """
    used = sum(g.slots for g in groups)
    if env.num_envs < used:
        raise ValueError(f"evaluation needs {used} environments, the env has {env.num_envs}")
    device = env.device
    plays, seeds, offset = [], [], 0
    for group in groups:
        plays.append(_GroupPlay(group, offset, env, obs_clip))
        seeds += [group.seed + i for i in range(group.slots)]
        offset += group.slots
    first = np.zeros(env.num_envs, dtype=bool)
    first[:used] = True
    obs, contacts = env.reset(seed=seeds + [None] * (env.num_envs - used), mask=first)
    running = torch.from_numpy(first).to(device)
    obs_t, contacts = obs[:used].float(), contacts[:used]
    space = env.env.single_action_space
    action_map = ActionMap(space.low, space.high, device)
    record = reward_fn is not None
    actions_full = torch.zeros((env.num_envs, space.shape[0]), device=device)
    num_steps = 0
    while num_steps % sync_every or bool(running.any()):
        samples = []
        for play in plays:
            _, actions, log_probs = play.sampler.sample(
                obs_t[play.rows], play.group.generator, deterministic, log_probs=record
            )
            executed = action_map(actions)
            actions_full[play.rows] = executed
            samples.append((executed, log_probs))
        active = running.clone()
        step = env.step(actions_full, mask=active)
        done = step.done[:used]
        next_t, next_contacts = step.obs[:used].float(), step.contacts[:used]
        for play, (executed, log_probs) in zip(plays, samples, strict=True):
            rows = play.rows
            play.active_counts.append(active[rows].sum())
            ended = done[rows]
            play.returns = torch.where(ended, step.episode_return[rows], play.returns)
            play.lengths = torch.where(ended, step.episode_length[rows], play.lengths)
            play.measures = torch.where(ended[:, None], step.episode_measures[rows], play.measures)
            if record:
                play.steps.append(
                    {
                        "obs": obs_t[rows],
                        "actions": executed,
                        "contacts": contacts[rows],
                        "next_obs": next_t[rows],
                        "next_contacts": next_contacts[rows],
                        "rewards": step.reward[rows].float(),
                        "dones": ended.float(),
                        "terminated": step.terminated[rows].float(),
                        "log_probs": log_probs,
                        "valid": active[rows].float(),
                        "starts": torch.full(
                            (rows.stop - rows.start,), float(num_steps == 0), device=device
                        ),
                    }
                )
        running[:used] &= ~done
        obs_t, contacts = next_t, next_contacts
        num_steps += 1
    return [play.score(reward_fn) for play in plays]
