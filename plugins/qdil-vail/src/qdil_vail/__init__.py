"""``vail``: Variational Adversarial Imitation Learning (Peng et al., ICLR 2019).

https://arxiv.org/abs/1810.00821. GAIL with a variational information bottleneck: an
encoder E(z | x) = N(μ(x), σ(x)²) feeds the discriminator D(z), and the discriminator loss
adds β (E_x[KL(E(z | x) ‖ N(0, I))] − I_c), with β adapted by dual gradient ascent
(β ← max(0, β + α_β (KL − I_c))). The reward follows the QD-IL code: −log(1 − σ(D(μ(x))) +
1e-8), evaluated at the encoder mean.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
import torch.nn.functional as F
from typing_extensions import override

from qdil.data import TransitionBatch
from qdil.rewards import register_reward
from qdil.rewards.adversarial import AdversarialReward
from qdil.rewards.nets import gradient_penalty, mlp

__all__ = ["VAIL"]


@register_reward("vail")
class VAIL(AdversarialReward):
    """VAIL: a discriminator behind a variational bottleneck.

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        hidden: encoder widths (QD-IL code: (100, 100)).
        latent_dim: bottleneck size (QD-IL code: 50).
        information_constraint: I_c (VDB paper and QD-IL code: 0.5).
        beta: initial bottleneck weight.
        beta_step: dual step size α_β (0 keeps β fixed, as the QD-IL code does).
        **kwargs: qdil's ``AdversarialReward`` options (use_measures, learning_rate, ...).
    """

    description = "VAIL (Peng et al. 2019): GAIL with a variational discriminator bottleneck"
    default_form = "log1-d"

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        hidden: Sequence[int] = (100, 100),
        latent_dim: int = 50,
        information_constraint: float = 0.5,
        beta: float = 1.0,
        beta_step: float = 1e-5,
        **kwargs: Any,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures, **kwargs)
        self.information_constraint = information_constraint
        self.beta_step = beta_step
        self.encoder = mlp(self.input_dim, hidden, 2 * latent_dim)
        self.head = mlp(latent_dim, (), 1)
        self.register_buffer("beta", torch.tensor(float(beta)))

    def encode(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and standard deviation (B, latent_dim) of E(z | x)."""
        mean, raw = self.encoder(x).chunk(2, dim=-1)
        return mean, torch.sigmoid(raw) + 1e-4

    @override
    def configure_optimizers(self) -> torch.optim.Optimizer:
        return torch.optim.Adam(self.parameters(), lr=self.learning_rate)

    @override
    def score(self, batch: TransitionBatch) -> torch.Tensor:
        mean, _ = self.encode(self.features(batch))
        return self.head(mean).squeeze(-1)

    @override
    def update(
        self, expert: TransitionBatch, policy: TransitionBatch, iteration: int
    ) -> dict[str, float]:
        optimizer = self.optimizers()
        sums = {"loss": 0.0, "kl": 0.0, "beta": 0.0, "expert_acc": 0.0, "policy_acc": 0.0}
        steps = 0
        for expert_mb, policy_mb in self.minibatches(expert, policy):
            x = torch.cat([self.features(expert_mb), self.features(policy_mb)])
            labels = torch.cat([torch.ones(len(expert_mb)), torch.zeros(len(policy_mb))])
            mean, std = self.encode(x)
            z = mean + std * torch.randn_like(std)
            logits = self.head(z).squeeze(-1)
            kl = 0.5 * (mean.square() + std.square() - 2 * std.log() - 1).sum(-1).mean()
            loss = F.binary_cross_entropy_with_logits(logits, labels)
            loss = loss + self.beta * (kl - self.information_constraint)
            if self.gp_weight:
                half = len(expert_mb)

                def critic(inputs: torch.Tensor) -> torch.Tensor:
                    return self.head(self.encode(inputs)[0]).squeeze(-1)

                loss = loss + self.gp_weight * gradient_penalty(critic, x[:half], x[half:])
            self.descend(optimizer, loss, "discriminator loss", iteration)
            with torch.no_grad():
                self.beta.copy_(
                    (self.beta + self.beta_step * (kl - self.information_constraint)).clamp_min(0)
                )
                accuracy = ((logits > 0).float() == labels).float()
            sums["loss"] += float(loss.detach())
            sums["kl"] += float(kl.detach())
            sums["beta"] += float(self.beta)
            sums["expert_acc"] += float(accuracy[: len(expert_mb)].mean())
            sums["policy_acc"] += float(accuracy[len(expert_mb) :].mean())
            steps += 1
        return {key: value / max(steps, 1) for key, value in sums.items()} | self.measure(
            expert, policy
        )
