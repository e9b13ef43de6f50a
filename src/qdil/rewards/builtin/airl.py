"""``airl``: Adversarial Inverse Reinforcement Learning (Fu, Luo & Levine, ICLR 2018).

:class:`AIRL`: a discriminator D = exp f / (exp f + π(a | s)) with f = g(s, a) + γ h(s') − h(s);
the score is f (default) or the discriminator's logit f − log π(a | s), and the reward is
that score (the ``raw`` form) unless ``reward_form`` names another. Equations and choices:
docs/rewards/airl.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import torch
from typing_extensions import override

from qdil.data import TransitionBatch
from qdil.rewards.adversarial import AdversarialReward, average
from qdil.rewards.nets import mlp
from qdil.rewards.registry import register_reward


@register_reward("airl")
class AIRL(AdversarialReward):
    """AIRL: f = g(s, a) + γ h(s') − h(s); reward f.

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        hidden: widths of g and h (the paper's discriminator: (100, 100)).
        gamma: discount of the shaping term.
        score_type: ``f`` (default) or ``logit`` (f − log π of the transition's policy): what the
            reward form receives.
        **kwargs: :class:`~qdil.rewards.adversarial.AdversarialReward` options.
    """

    description = "AIRL (Fu et al. 2018): shaped reward f = g(s,a) + gamma h(s') - h(s)"
    needs_next_obs = True
    needs_log_probs = True

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        hidden: Sequence[int] = (100, 100),
        gamma: float = 0.99,
        score_type: Literal["f", "logit"] = "f",
        **kwargs: Any,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures, **kwargs)
        if score_type not in ("f", "logit"):
            raise ValueError(f"AIRL: score_type must be f or logit, got {score_type!r}")
        self.gamma = gamma
        self.score_type = score_type
        self.g = mlp(self.input_dim, hidden, 1)
        self.h = mlp(obs_dim, hidden, 1)

    def _inputs(self, batch: TransitionBatch) -> torch.Tensor:
        """(B, input_dim + obs_dim + 1): x, normalised s', done."""
        return torch.cat(
            [self.features(batch), self.normalize_obs(batch.next_obs), batch.dones[:, None]], dim=1
        )

    def f(self, inputs: torch.Tensor) -> torch.Tensor:
        """The shaped score g + γ h(s') − h(s), (B,), from :meth:`_inputs`; h(final) = 0."""
        x = inputs[:, : self.input_dim]
        next_obs = inputs[:, self.input_dim : self.input_dim + self.obs_dim]
        done = inputs[:, -1]
        obs = x[:, : self.obs_dim]
        g = self.g(x).squeeze(-1)
        return g + self.gamma * (1 - done) * self.h(next_obs).squeeze(-1) - self.h(obs).squeeze(-1)

    @override
    def score(self, batch: TransitionBatch) -> torch.Tensor:
        f = self.f(self._inputs(batch))
        if self.score_type == "logit":
            return f - torch.nan_to_num(batch.log_probs, nan=0.0)
        return f

    @override
    def update(
        self, expert: TransitionBatch, policy: TransitionBatch, iteration: int
    ) -> dict[str, float]:
        for name, batch in (("expert", expert), ("policy", policy)):
            if not torch.isfinite(batch.log_probs).all():
                raise ValueError(f"airl needs the policy's log-probabilities of the {name} batch")
        optimizer = self.optimizers()
        steps = []
        for expert_mb, policy_mb in self.minibatches(expert, policy):
            in_e, in_p = self._inputs(expert_mb), self._inputs(policy_mb)
            logit_e = self.f(in_e) - expert_mb.log_probs
            logit_p = self.f(in_p) - policy_mb.log_probs
            gp = self.penalty(self.f, in_e, in_p)
            steps.append(self.classify(optimizer, logit_e, logit_p, gp, iteration))
        return average(steps) | self.measure(expert, policy)
