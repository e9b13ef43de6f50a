"""``lsgail``: a least-squares discriminator reward, the example of the reward-plugin guide.

The discriminator D(x) is a small MLP trained as in LSGAN (Mao et al. 2017,
https://arxiv.org/abs/1611.04076) with the targets and the reward of AMP (Peng et al. 2021,
https://arxiv.org/abs/2104.02180):

- loss  = E_D[(D(x) − 1)²] + E_π[(D(x) + 1)²] + (w/2)·E_D[‖∇ₓD(x)‖²]
  (expert target +1, policy target −1, a zero-centred gradient penalty on expert inputs);
- reward r(x) = max(0, 1 − (D(x) − 1)²/4), in [0, 1]: 1 where D(x) = 1 (expert-like),
  0 where D(x) ≤ −1 (policy-like).

x = (s, a), or (s, a, δ(s)) with ``use_measures``, standardised with the demonstrations'
statistics by :class:`~qdil.rewards.adversarial.AdversarialReward`, which also supplies the
(expert, policy) minibatches. Copy this file into your plugin package
(``src/qdil_my_reward/example_reward.py``, with the entry point of the reward-plugin guide's
section 2) or into a local plugin folder (``./plugins`` or one on ``$QDIL_PLUGIN_PATH``);
``qdil rewards list`` then shows ``lsgail``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from typing_extensions import override

from qdil.data import TransitionBatch
from qdil.rewards import register_reward
from qdil.rewards.adversarial import AdversarialReward
from qdil.rewards.nets import mlp


@register_reward("lsgail")
class LeastSquaresGAIL(AdversarialReward):
    """Least-squares discriminator (LSGAN loss, AMP reward): r = max(0, 1 − (D − 1)²/4).

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k, the number of foot-contact flags in δ(s).
        hidden: widths of the discriminator's tanh hidden layers.
        **kwargs: the shared options of
            :class:`~qdil.rewards.adversarial.AdversarialReward`: ``use_measures``,
            ``learning_rate``, ``batch_size``, ``epochs`` and ``gp_weight`` (here w, the
            weight of the expert gradient penalty; 0 disables it).
    """

    description = "least-squares discriminator (LSGAN loss, AMP reward), the guide's example"

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        hidden: Sequence[int] = (64, 64),
        **kwargs: Any,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures, **kwargs)
        self.discriminator = mlp(self.input_dim, hidden, 1)

    def discriminate(self, x: torch.Tensor) -> torch.Tensor:
        """(B,) discriminator output D(x) of inputs x (B, input_dim)."""
        return self.discriminator(x).squeeze(-1)

    @override
    def configure_optimizers(self) -> torch.optim.Optimizer:
        return torch.optim.Adam(self.parameters(), lr=self.learning_rate)

    @override
    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        d = self.discriminate(self.features(batch))
        return (1 - 0.25 * (d - 1).square()).clamp_min(0.0)

    def expert_gradient_penalty(self, x_e: torch.Tensor) -> torch.Tensor:
        """E_D[‖∇ₓD(x)‖²] on expert inputs (zero-centred, as in AMP)."""
        x_e = x_e.detach().requires_grad_(True)
        (grad,) = torch.autograd.grad(self.discriminate(x_e).sum(), x_e, create_graph=True)
        return grad.square().sum(-1).mean()

    @override
    def update(
        self, expert: TransitionBatch, policy: TransitionBatch, iteration: int
    ) -> dict[str, float]:
        optimizer = self.optimizers()
        sums = {"loss": 0.0, "gp": 0.0, "expert_score": 0.0, "policy_score": 0.0}
        steps = 0
        for expert_mb, policy_mb in self.minibatches(expert, policy):
            x_e, x_p = self.features(expert_mb), self.features(policy_mb)
            d_e, d_p = self.discriminate(x_e), self.discriminate(x_p)
            loss = (d_e - 1).square().mean() + (d_p + 1).square().mean()
            gp = self.expert_gradient_penalty(x_e) if self.gp_weight else torch.zeros(())
            loss = loss + 0.5 * self.gp_weight * gp
            self.descend(optimizer, loss, "discriminator loss", iteration)
            for key, value in (
                ("loss", loss),
                ("gp", gp),
                ("expert_score", d_e.mean()),
                ("policy_score", d_p.mean()),
            ):
                sums[key] += float(value.detach())
            steps += 1
        return {key: value / max(steps, 1) for key, value in sums.items()}
