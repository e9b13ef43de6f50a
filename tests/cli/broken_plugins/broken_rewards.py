"""Reward plugins that break the contract or turn NaN: ``qdil fit`` must refuse them clearly.

Registered only by the ``broken_plugins`` fixture of tests/cli/test_errors.py, which points
``$QDIL_PLUGIN_PATH`` at this folder in a copy of the registry; each class is as small as the
case it stands for, and none needs demonstrations.
"""

from __future__ import annotations

import torch

from qdil.data import TransitionBatch
from qdil.rewards import RewardModel, register_reward


class _Linear(RewardModel):
    """A learned linear reward of the observation, without update(): what the models share."""

    needs_demos = False

    def __init__(self, obs_dim: int, action_dim: int, num_measures: int) -> None:
        super().__init__(obs_dim, action_dim, num_measures)
        self.net = torch.nn.Linear(obs_dim, 1)

    def configure_optimizers(self) -> torch.optim.Optimizer:
        return torch.optim.SGD(self.parameters(), lr=0.0)

    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        return self.net(batch.obs).squeeze(-1)


@register_reward("no_reward_method")
class NoRewardMethod(RewardModel):
    """A fixed reward that forgot reward()."""

    learned = False
    needs_demos = False


@register_reward("no_update_method")
class NoUpdateMethod(_Linear):
    """A learned reward that forgot update()."""


@register_reward("no_learning_methods")
class NoLearningMethods(RewardModel):
    """A learned reward (the default) with reward() only."""

    needs_demos = False

    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        return batch.obs.sum(-1)


@register_reward("nan_fixed")
class NaNFixed(RewardModel):
    """A fixed reward that is NaN everywhere."""

    learned = False
    needs_demos = False

    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        return torch.full((len(batch),), float("nan"))


@register_reward("nan_untrained")
class NaNUntrained(_Linear):
    """A learned reward that is NaN before any update."""

    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        return super().reward(batch) * float("nan")

    def update(
        self, expert: TransitionBatch | None, policy: TransitionBatch, iteration: int
    ) -> dict[str, float]:
        return {}


@register_reward("nan_after_update")
class NaNAfterUpdate(_Linear):
    """A learned reward whose first update diverges (its weights become NaN)."""

    def update(
        self, expert: TransitionBatch | None, policy: TransitionBatch, iteration: int
    ) -> dict[str, float]:
        with torch.no_grad():
            self.net.weight.fill_(float("nan"))
        return {}
