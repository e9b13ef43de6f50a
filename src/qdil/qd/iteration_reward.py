"""The rewards an iteration trains and scores with, and the reward model's one update.

:func:`reward_functions` gives the estimator's training reward (:class:`TrainReward`: the
model's per-step rewards, checked finite, tallied for the survival figures, plus the
absorbing tail where episodes terminate) and the evaluation's objective;
:func:`update_reward` is the model's once-per-iteration update (decision D3);
:func:`walk_survival` the survival figures of what the walk optimises.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from qdil.data import Rollout, TransitionBatch
from qdil.qd.absorbing import AbsorbingTail
from qdil.qd.survival import SurvivalTally
from qdil.qd.vppo import walk_rewards
from qdil.reductions import sum_over
from qdil.timing import REWARD_MODEL, section

if TYPE_CHECKING:
    from qdil.rewards.base import RewardModel


class TrainReward:
    """The per-step rewards the estimator trains on, a finiteness check, their mean per step.

    Args:
        reward: the reward model that scores the rollouts.
        iteration: the QD iteration (named by the finiteness check).
        tail: what an absorbing state adds where episodes terminate (``None``: nothing);
            the tally, the mean and ``returned`` leave it out.
    """

    def __init__(
        self, reward: RewardModel, iteration: int, tail: AbsorbingTail | None = None
    ) -> None:
        self.reward = reward
        self.iteration = iteration
        self.tail = tail
        self.total = 0.0
        self.steps = 0
        self.survival = SurvivalTally()
        self.returned: list[torch.Tensor] = []  # this phase's rewards, in call order

    def __call__(self, rollout: Rollout) -> torch.Tensor:
        """(T, N) rewards of a training rollout (visits count toward the bonus)."""
        with section(REWARD_MODEL):
            rewards = self.reward.predict_reward(rollout, update=True)
        self.reward.check_finite(rewards, "rewards", self.iteration)
        valid = rollout.valid > 0
        self.total += float(sum_over(rewards[valid], 0))  # thread-invariant over 384,000 steps
        self.steps += int(valid.sum())
        self.survival.add(rollout, rewards)
        self.returned.append(rewards)
        return rewards if self.tail is None else rewards + self.tail(rollout)

    @property
    def per_step(self) -> float:
        """Mean reward per valid training step so far (NaN before any rollout)."""
        return self.total / self.steps if self.steps else float("nan")


def reward_functions(
    reward: RewardModel,
    iteration: int,
    horizon: int | None,
    gamma: float | None,
    scores_learned: bool,
) -> tuple[TrainReward, Callable[[Rollout], torch.Tensor] | None]:
    """The rewards the estimator trains on and the evaluation's objective, checked finite.

    Args:
        reward: the run's reward model.
        iteration: the QD iteration they serve.
        horizon: the episodes' time limit (``env.max_episode_steps``); absorbing states
            need it.
        gamma: the discount of an estimator that discounts per-step rewards (VPPO's GAE);
            ``None`` for one that scores whole episodes (ES gradients), which gets the
            episodes' absorbing tail.
        scores_learned: whether evaluations score under the reward model; ``False`` (true
            fitness or the true reward) gives no evaluation reward.

    Returns:
        The training reward and the evaluation's (T, N) reward function, or ``None``.
    """
    train_tail = eval_tail = None
    if reward.absorbing:
        if horizon is None:
            raise ValueError("absorbing states need env.max_episode_steps (the time limit)")
        eval_tail = AbsorbingTail(reward, horizon, None, iteration)
        train_tail = AbsorbingTail(reward, horizon, gamma, iteration)
    train_reward = TrainReward(reward, iteration, train_tail)

    def eval_reward(rollout: Rollout) -> torch.Tensor:
        with section(REWARD_MODEL):
            rewards = reward.predict_reward(rollout)
        reward.check_finite(rewards, "rewards", iteration)
        return rewards if eval_tail is None else rewards + eval_tail(rollout)

    return train_reward, (eval_reward if scores_learned else None)


def walk_survival(
    rollouts: list[Rollout], rewards: list[torch.Tensor], coefficients: np.ndarray
) -> dict[str, float]:
    """The survival figures of what the walk optimises, c_0·r̂ + Σ_j c_j·δ_j.

    VPPO's walk calls the reward once per rollout; an estimator whose walk plays no
    rollouts (ES gradients) gets none.
    """
    if not rollouts or len(rollouts) != len(rewards):
        return {}
    tally = SurvivalTally(prefix="walk_")
    for rollout, learned in zip(rollouts, rewards, strict=True):
        c = torch.as_tensor(coefficients, dtype=learned.dtype, device=learned.device)
        tally.add(rollout, walk_rewards(c, learned, rollout.next_contacts))
    return tally.metrics()


def update_reward(
    reward: RewardModel, iteration: int, expert: Any, policy: TransitionBatch
) -> dict[str, float]:
    """The reward model's once-per-iteration update (decision D3), its metrics checked finite."""
    with section(REWARD_MODEL):
        reward_metrics = reward.update(expert, policy, iteration)
        if reward.absorbing:
            reward.price_absorbing(policy)
    for key, value in reward_metrics.items():
        reward.check_finite(torch.as_tensor(value), f"update metric {key}", iteration)
    return reward_metrics
