"""Evaluations whose physics, policies and episodes stay on one torch device.

The twin of :func:`~qdil.rl.episodes.evaluate_policies` for device backends
(``env.backend: warp``): it steps the environment through its torch face
(:class:`~qdil.envs.torch_vector.TorchVectorEnv`). What goes to the host, and when: whether
any episode still runs, once every ``sync_every`` steps (the steps after the last episode
ended change nothing: every simulation sits out of them), and the scores once at the end,
as numpy arrays for pyribs.

The same seeds give the same rollouts as the numpy path on the same backend
(``tests/rl/test_collect_device.py``).
"""

from __future__ import annotations

import numpy as np
import torch

from qdil.data import Rollout
from qdil.envs.torch_vector import TorchVectorEnv
from qdil.rl.collect import ActionMap, RewardFn
from qdil.rl.episodes import Evaluation, EvaluationGroup
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from qdil.rl.sampler import PolicySampler


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
