"""``true_reward``: the task's own reward; with it, the QD loop is PPGA (the expert)."""

from __future__ import annotations

import torch
from typing_extensions import override

from qdil.data import Rollout, TransitionBatch
from qdil.rewards.base import RewardModel
from qdil.rewards.registry import register_reward


@register_reward("true_reward")
class TrueReward(RewardModel):
    """The environment's true reward (PPGA-trueReward, the paper's expert row).

    Not imitation: it reads the reward the other models must do without. Use it to train
    the expert archives that demonstrations come from.
    """

    description = "the task's true reward: PPGA itself, the expert that makes demonstrations"
    learned = False
    needs_demos = False
    is_true_reward = True
    prefers_expert = None

    @override
    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        raise NotImplementedError(
            "true_reward reads rewards from rollouts (predict_reward); transitions carry none"
        )

    @override
    @torch.no_grad()
    def predict_reward(self, rollout: Rollout, *, update: bool = False) -> torch.Tensor:
        return rollout.rewards.clone()
