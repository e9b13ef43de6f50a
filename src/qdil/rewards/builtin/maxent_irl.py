"""``maxentirl``: maximum-entropy IRL, neural reward (Ziebart et al. 2008; Wulfmeier et al. 2015).

https://cdn.aaai.org/AAAI/2008/AAAI08-227.pdf. The reward r_θ(s, a) is raised on expert
transitions and lowered on the policy's: loss = E_π[r_θ] − E_D[r_θ] (the sample-based
maximum-entropy gradient, as f-IRL's ``maxentirl_loss``), plus a gradient penalty and
weight decay. The loss is linear in r, so the reward is clamped to ±``clamp``.
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


@register_reward("maxentirl")
class MaxEntIRL(AdversarialReward):
    """MaxEntIRL: a reward network trained on E_π[r] − E_D[r].

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        hidden: reward-network widths (the paper's table: (100, 100)).
        clamp: bound of the reward (f-IRL: 10).
        weight_decay: Adam weight decay (f-IRL: 1e-3).
        **kwargs: :class:`~qdil.rewards.adversarial.AdversarialReward` options.
    """

    description = "MaxEntIRL (Ziebart 2008): reward net trained on E_pi[r] - E_D[r]"

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        hidden: Sequence[int] = (100, 100),
        clamp: float = 10.0,
        weight_decay: float = 1e-3,
        **kwargs: Any,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures, **kwargs)
        self.clamp = clamp
        self.weight_decay = weight_decay
        self.net = mlp(self.input_dim, hidden, 1)
        # E_π[r] − E_D[r] cannot see a constant offset: the last layer has no bias to learn
        self.net[-1] = torch.nn.Linear(self.net[-1].in_features, 1, bias=False)
        torch.nn.init.xavier_uniform_(self.net[-1].weight)

    def raw(self, x: torch.Tensor) -> torch.Tensor:
        """(B,) clamped reward of inputs x."""
        return self.net(x).squeeze(-1).clamp(-self.clamp, self.clamp)

    @override
    def configure_optimizers(self) -> torch.optim.Optimizer:
        return torch.optim.Adam(
            self.parameters(), lr=self.learning_rate, weight_decay=self.weight_decay
        )

    @override
    def score(self, batch: TransitionBatch) -> torch.Tensor:
        return self.raw(self.features(batch))

    @override
    def update(
        self, expert: TransitionBatch, policy: TransitionBatch, iteration: int
    ) -> dict[str, float]:
        optimizer = self.optimizers()
        steps = []
        for expert_mb, policy_mb in self.minibatches(expert, policy):
            x_e, x_p = self.features(expert_mb), self.features(policy_mb)
            r_e, r_p = self.raw(x_e), self.raw(x_p)
            gp = self.penalty(self.raw, x_e, x_p)
            loss = r_p.mean() - r_e.mean() + self.gp_weight * gp
            self.descend(optimizer, loss, "reward loss", iteration)
            values = {
                "loss": loss,
                "gp": gp,
                "reward_expert": r_e.mean(),
                "reward_policy": r_p.mean(),
            }
            steps.append({key: float(value.detach()) for key, value in values.items()})
        return average(steps) | self.measure(expert, policy)
