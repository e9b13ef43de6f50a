"""``giril``: Generative Intrinsic Reward driven Imitation Learning (Yu, Lyu & Tsang, ICML 2020).

https://arxiv.org/abs/2002.01515. A conditional VAE is pretrained on the demonstrations
only, then frozen: the encoder q(z | s, s') infers an action-like latent (z ∈ R^A, inverse
dynamics) and the decoder p(s' | s, z) predicts the next state (forward dynamics). Loss:
‖ŝ' − s'‖² + β·KL(q ‖ N(0, I)) + λ_a·‖z − a‖² (means over dimensions; the KL summed over
latent dimensions and averaged over the batch). The reward is the decoder's prediction
error with the true action, r = mean_d (G(s, a)_d − s'_d)², on standardised states: a
curiosity signal that is high where the policy leaves the demonstrated dynamics.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from typing_extensions import override

from qdil.data import TransitionBatch
from qdil.demos.dataset import DemoSet
from qdil.rewards.base import RewardModel
from qdil.rewards.nets import mlp
from qdil.rewards.registry import register_reward


@register_reward("giril")
class GIRIL(RewardModel):
    """GIRIL: a pretrained conditional VAE's next-state prediction error.

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        hidden: encoder and decoder widths (the paper: (100, 100)).
        pretrain_epochs: passes over the demonstrations (the paper: 10,000).
        batch_size: pretraining minibatch (the paper: 32).
        learning_rate: Adam learning rate (the paper: 3e-4).
        kl_weight: β.
        action_weight: λ_a (the authors' script: 0.01).
        use_measures: condition on δ: states become (s, δ(s)).
    """

    description = "GIRIL (Yu et al. 2020): pretrained conditional-VAE curiosity reward"
    learned = False
    needs_next_obs = True
    prefers_expert = False

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        hidden: Sequence[int] = (100, 100),
        pretrain_epochs: int = 100,
        batch_size: int = 32,
        learning_rate: float = 3e-4,
        kl_weight: float = 1.0,
        action_weight: float = 0.01,
        use_measures: bool = False,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures)
        if pretrain_epochs < 0 or batch_size < 1:
            raise ValueError("giril: pretrain_epochs must be >= 0 and batch_size positive")
        self.pretrain_epochs, self.batch_size, self.learning_rate = (
            pretrain_epochs,
            batch_size,
            learning_rate,
        )
        self.kl_weight, self.action_weight, self.use_measures = (
            kl_weight,
            action_weight,
            use_measures,
        )
        state = obs_dim + (num_measures if use_measures else 0)
        self.encoder = mlp(2 * state, hidden, 2 * action_dim)
        self.decoder = mlp(state + action_dim, hidden, state)
        self.pretrain_loss = float("nan")

    def states(self, obs: torch.Tensor, contacts: torch.Tensor) -> torch.Tensor:
        """(B, state) standardised observations, with δ when measure-conditioned."""
        parts = [self.normalize_obs(obs)]
        if self.use_measures:
            parts.append(contacts)
        return torch.cat(parts, dim=-1)

    def loss(self, batch: TransitionBatch) -> torch.Tensor:
        """The conditional VAE's loss on a batch."""
        s = self.states(batch.obs, batch.contacts)
        s_next = self.states(batch.next_obs, batch.next_contacts)
        mean, log_var = self.encoder(torch.cat([s, s_next], -1)).chunk(2, -1)
        z = mean + (0.5 * log_var).exp() * torch.randn_like(mean)
        prediction = self.decoder(torch.cat([s, z], -1))
        kl = -0.5 * (1 + log_var - mean.square() - log_var.exp()).sum(-1).mean()
        elbo = (prediction - s_next).square().mean() + self.kl_weight * kl
        return (
            elbo + self.action_weight * (z - self.normalize_actions(batch.actions)).square().mean()
        )

    @override
    def pretrain(self, demos: DemoSet | None) -> None:
        if demos is None:
            raise ValueError("giril needs demonstrations (demos.path)")
        batch = demos.transitions()
        optimizer = torch.optim.Adam(self.parameters(), lr=self.learning_rate)
        self.train()
        for _ in range(self.pretrain_epochs):
            order = torch.randperm(len(batch))
            for start in range(0, len(batch), self.batch_size):
                loss = self.loss(batch[order[start : start + self.batch_size]])
                optimizer.zero_grad()
                loss.backward()
                optimizer.step()
        with torch.no_grad():
            self.pretrain_loss = float(self.loss(batch))

    @override
    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        s = self.states(batch.obs, batch.contacts)
        s_next = self.states(batch.next_obs, batch.next_contacts)
        prediction = self.decoder(torch.cat([s, self.normalize_actions(batch.actions)], -1))
        return (prediction - s_next).square().mean(-1)
