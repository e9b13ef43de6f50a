"""Synthetic, separable transitions for reward-model tests: expert around +2, policy around -2."""

from __future__ import annotations

import numpy as np
import torch
from lightning import Fabric

from qdil.data import Rollout, TransitionBatch
from qdil.demos.dataset import DemoSet
from qdil.rewards.base import RewardModel

OBS, ACT, K = 5, 2, 2


def synthetic(center: float, size: int, seed: int) -> TransitionBatch:
    """Transitions around ``center``: observations, actions and contact patterns differ."""
    g = torch.Generator().manual_seed(seed)
    obs = center + 0.5 * torch.randn(size, OBS, generator=g)
    actions = (0.4 * np.sign(center) + 0.1 * torch.randn(size, ACT, generator=g)).clamp(-1, 1)
    contacts = torch.tensor([[1.0, 0.0] if center > 0 else [0.0, 1.0]]).repeat(size, 1)
    next_obs = center + 0.5 * torch.randn(size, OBS, generator=g)
    dones = torch.zeros(size)
    dones[-1] = 1.0
    return TransitionBatch(
        obs, actions, contacts, next_obs, contacts.clone(), dones, torch.full((size,), -1.0)
    )


def demos_of(batch: TransitionBatch) -> DemoSet:
    """A two-episode demonstration set holding ``batch``."""
    n = len(batch)
    return DemoSet(
        task="Walker2d-v5",
        obs=batch.obs.double().numpy(),
        actions=batch.actions.double().numpy(),
        contacts=batch.contacts.numpy(),
        rewards=np.zeros(n),
        next_obs=batch.next_obs.double().numpy(),
        next_contacts=batch.next_contacts.numpy(),
        episode_ends=np.array([n // 2, n]),
        terminated=np.array([True, False]),
    )


def as_rollout(batch: TransitionBatch, envs: int = 1) -> Rollout:
    """Transitions laid out time-major, (len / envs, envs)."""
    steps = len(batch) // envs

    def tm(x: torch.Tensor) -> torch.Tensor:
        return x[: steps * envs].reshape(envs, steps, *x.shape[1:]).transpose(0, 1).contiguous()

    starts = torch.zeros(steps, envs)
    starts[0] = 1.0
    return Rollout(
        obs=tm(batch.obs),
        actions=tm(batch.actions),
        contacts=tm(batch.contacts),
        next_obs=tm(batch.next_obs),
        next_contacts=tm(batch.next_contacts),
        rewards=torch.randn(steps, envs),
        dones=tm(batch.dones),
        terminated=tm(batch.dones),
        log_probs=tm(batch.log_probs),
        valid=torch.ones(steps, envs),
        starts=starts,
    )


def train(model: RewardModel, expert: TransitionBatch, policy: TransitionBatch, updates: int):
    """Set ``model`` up as the QD loop does (Fabric, demos, pretraining) and update it.

    Returns:
        The model and the metrics of each update.
    """
    if model.learned:
        optimizers = model.configure_optimizers()
        optimizers = optimizers if isinstance(optimizers, list) else [optimizers]
        Fabric(accelerator="cpu", devices=1).setup(model, *optimizers)
    demos = demos_of(expert) if model.needs_demos else None
    model.setup(demos)
    model.pretrain(demos)
    metrics = (
        [model.update(expert, policy, iteration=i) for i in range(updates)] if model.learned else []
    )
    return model, metrics
