"""``gail``: Generative Adversarial Imitation Learning (Ho & Ermon, NeurIPS 2016).

https://arxiv.org/abs/1606.03476. A discriminator D(x) = σ(logit(x)) learns to tell expert
transitions (label 1) from the policy's (label 0) with binary cross-entropy plus a gradient
penalty; its score is the logit, and the policy is rewarded with r = −log(1 − D(x) + 1e-8)
(the ``log1-d`` form, the QD-IL code's) unless ``reward_form`` names another. With
``use_measures`` it is the measure-conditioned GAIL of Eq. (GAIL) in the paper.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from typing_extensions import override

from qdil.data import TransitionBatch
from qdil.rewards.adversarial import AdversarialReward, average
from qdil.rewards.nets import mlp
from qdil.rewards.registry import register_reward


@register_reward("gail")
class GAIL(AdversarialReward):
    """GAIL: a transition discriminator; score its logit, reward −log(1 − D) by default.

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        hidden: discriminator widths (the paper: (100, 100)).
        **kwargs: :class:`~qdil.rewards.adversarial.AdversarialReward` options
            (``reward_form``: ``log1-d`` by default; ``raw`` is the logit itself).
    """

    description = "GAIL (Ho & Ermon 2016): discriminator reward -log(1-D)"
    default_form = "log1-d"

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        hidden: Sequence[int] = (100, 100),
        **kwargs: Any,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures, **kwargs)
        self.discriminator = mlp(self.input_dim, hidden, 1)

    def logits(self, x: torch.Tensor) -> torch.Tensor:
        """(B,) discriminator logits of inputs x (B, input_dim)."""
        return self.discriminator(x).squeeze(-1)

    @override
    def score(self, batch: TransitionBatch) -> torch.Tensor:
        return self.logits(self.features(batch))

    @override
    def update(
        self, expert: TransitionBatch, policy: TransitionBatch, iteration: int
    ) -> dict[str, float]:
        optimizer = self.optimizers()
        steps = []
        for expert_mb, policy_mb in self.minibatches(expert, policy):
            x_e, x_p = self.features(expert_mb), self.features(policy_mb)
            gp = self.penalty(self.logits, x_e, x_p)
            steps.append(
                self.classify(optimizer, self.logits(x_e), self.logits(x_p), gp, iteration)
            )
        return average(steps) | self.measure(expert, policy)
