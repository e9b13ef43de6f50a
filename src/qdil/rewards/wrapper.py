"""``BonusWrapper``: what every exploration bonus that wraps a reward model shares.

A bonus changes only the rewards handed to RL (and, for some bonuses, to the evaluations);
the wrapped model's setup, pretraining, training and state go through untouched. The
wrapper also measures the balance a user watches: the learned reward and the bonus per
valid training step, reported by ``update`` and reset every QD iteration.

The bonuses: :class:`~qdil.rewards.bonus.ExplorationBonus` (``bonus.type: single_step``,
WQDIL's decision D5) and :class:`~qdil.rewards.ebc.EBCBonus` (``bonus.type: ebc``).
"""

from __future__ import annotations

from typing import Any

import torch
from typing_extensions import override

from qdil.data import Rollout, TransitionBatch
from qdil.demos.dataset import DemoSet
from qdil.reductions import sum_over
from qdil.rewards.base import RewardModel


class BonusWrapper(RewardModel):
    """Base of the bonus wrappers: forwards the model's life cycle, adds :meth:`added`.

    Subclasses implement :meth:`added` and may add metrics with :meth:`bonus_metrics`.

    Args:
        model: the wrapped reward model.
        weight: the bonus's multiplier.
        suffix: appended to the model's name (``gail+bonus``).
    """

    def __init__(self, model: RewardModel, weight: float, suffix: str) -> None:
        super().__init__(model.obs_dim, model.action_dim, model.num_measures)
        self.model = model
        self.weight = weight
        # sums over this iteration's valid training steps: learned reward, bonus, steps
        self._balance = torch.zeros(3, dtype=torch.float64)
        self.name = f"{model.name}+{suffix}" if model.name else suffix
        self.learned = model.learned
        self.needs_demos = model.needs_demos
        self.needs_log_probs = model.needs_log_probs
        self.needs_next_obs = model.needs_next_obs
        self.use_measures = model.use_measures
        self.prefers_expert = model.prefers_expert
        self.absorbing = model.absorbing
        # never is_true_reward: the true reward plus a bonus is not the true reward, so the
        # archive objective must go through predict_reward

    def added(self, rollout: Rollout, update: bool) -> torch.Tensor | None:
        """(T, N) float32 bonus added to the model's rewards, or None where nothing is added.

        Args:
            rollout: time-major transitions.
            update: a training rollout (its visits count); False for evaluation episodes.
        """
        raise NotImplementedError(f"{type(self).__name__} must implement added(rollout, update)")

    def bonus_metrics(self) -> dict[str, float]:
        """Metrics of the bonus's own state, logged after the model's (default: none)."""
        return {}

    @override
    def setup(self, demos: DemoSet | None) -> None:
        self.model.setup(demos)

    @override
    def pretrain(self, demos: DemoSet | None) -> None:
        self.model.pretrain(demos)

    @override
    def configure_optimizers(self) -> Any:
        return self.model.configure_optimizers()

    @override
    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        return self.model.reward(batch)

    @override
    def absorbing_reward(self, batch: TransitionBatch) -> torch.Tensor:
        # no bonus in the absorbing state: it is no cell of the archive and counts no visit
        return self.model.absorbing_reward(batch)

    @override
    def price_absorbing(self, policy: TransitionBatch) -> None:
        self.model.price_absorbing(policy)

    @override
    def update(
        self, expert: TransitionBatch | None, policy: TransitionBatch, iteration: int
    ) -> dict[str, float]:
        metrics = self.model.update(expert, policy, iteration)
        learned, bonus, steps = self._balance.tolist()
        self._balance.zero_()
        steps = max(steps, 1.0)
        return {
            **metrics,
            "learned_per_step": learned / steps,
            "bonus_per_step": bonus / steps,
            **self.bonus_metrics(),
        }

    @override
    @torch.no_grad()
    def predict_reward(self, rollout: Rollout, *, update: bool = False) -> torch.Tensor:
        base = self.model.predict_reward(rollout, update=update)
        bonus = self.added(rollout, update)
        if update:  # the balance a user watches: learned reward and bonus per training step
            valid = rollout.valid > 0
            # a paper rollout has 384,000 steps: sum_over keeps the sums thread-invariant
            added = float(sum_over(bonus[valid], 0)) if bonus is not None else 0.0
            self._balance += torch.tensor(
                [float(sum_over(base[valid], 0)), added, float(valid.sum())], dtype=torch.float64
            )
        return base if bonus is None else base + bonus

    @override
    def check_finite(self, value: torch.Tensor, what: str, iteration: int) -> None:
        # the bonuses are bounded: non-finite values come from the wrapped model, which the
        # message must name (with its own advice: learned or fixed)
        self.model.check_finite(value, what, iteration)

    @override
    def extra_state(self) -> dict[str, Any]:
        return self.model.extra_state()

    @override
    def load_extra_state(self, state: dict[str, Any]) -> None:
        self.model.load_extra_state(state)
