"""The WAE family of WQDIL (Yu et al., AAMAS 2025, https://arxiv.org/abs/2411.06965).

:class:`WAEReward`: a Wasserstein auto-encoder embeds (s, a), or (s, a, δ(s)) with measure
conditioning, and a latent adversary scores the codes. :class:`WAEGAIL`, :class:`WAEWGAIL`,
:class:`MCWAEWGAIL` and :class:`MCWAEGAIL` register ``wae_gail``, ``wae_wgail``,
``mcwae_wgail`` and ``mcwae_gail``. Equations, decisions D6 and D7 and the choices the paper
leaves open: docs/rewards/wae_wgail.md and docs/rewards/wae_gail.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
import torch.nn.functional as F
from typing_extensions import override

from qdil.data import TransitionBatch
from qdil.rewards.adversarial import AdversarialReward, MeasureConditioned, average
from qdil.rewards.nets import mlp
from qdil.rewards.registry import register_reward


class WAEReward(AdversarialReward):
    """Shared machinery of the WAE reward models (not registered itself).

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        latent_dim: size of z (the paper does not give it). 32 (Walker2d's and
            HalfCheetah's inputs have 25 numbers) keeps the action in the code: with 8 the
            critic hardly tells a good action from a bad one in the same state
            (``benchmarks/probes/reward_actions.py``, docs/rewards/balance.md).
        hidden: widths of encoder, decoder and latent adversary (the paper: (100, 100)).
        regularization: λ (the paper: 1).
        **kwargs: :class:`~qdil.rewards.adversarial.AdversarialReward` options. The score
            is the critic's value D(z̄) at the encoder mean; ``reward_form`` is ``log1-d``
            (−log(1 − σ(D(z̄)) + 1e-8)) by default, and the critic's statistics are
            measured and logged after every update whatever the form.
    """

    default_form = "log1-d"
    always_measures = True

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        latent_dim: int = 32,
        hidden: Sequence[int] = (100, 100),
        regularization: float = 1.0,
        **kwargs: Any,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures, **kwargs)
        self.latent_dim = latent_dim
        self.regularization = regularization
        self.encoder = mlp(self.input_dim, hidden, 2 * latent_dim)
        self.decoder = mlp(latent_dim, hidden, self.input_dim)
        self.adversary = mlp(latent_dim, hidden, 1)

    def encode(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and log-variance (B, latent_dim) of Q_φ(z | x)."""
        mean, log_var = self.encoder(x).chunk(2, dim=-1)
        return mean, log_var.clamp(-10.0, 10.0)

    def sample(self, x: torch.Tensor) -> torch.Tensor:
        """A code z ~ Q_φ(z | x), by reparameterisation."""
        mean, log_var = self.encode(x)
        return mean + (0.5 * log_var).exp() * torch.randn_like(mean)

    def critic(self, z: torch.Tensor) -> torch.Tensor:
        """(B,) latent adversary output (a logit, or a Wasserstein critic value)."""
        return self.adversary(z).squeeze(-1)

    def reconstruction(self, x: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """Mean over the batch of f_c(x, G(z)) = ‖x − G(z)‖²."""
        return (x - self.decoder(z)).square().sum(-1).mean()

    @override
    def configure_optimizers(self) -> list[torch.optim.Optimizer]:
        autoencoder = [*self.encoder.parameters(), *self.decoder.parameters()]
        return [
            torch.optim.Adam(autoencoder, lr=self.learning_rate),
            torch.optim.Adam(self.adversary.parameters(), lr=self.learning_rate),
        ]

    @override
    def score(self, batch: TransitionBatch) -> torch.Tensor:
        """(B,) critic values D(z̄) at the encoder mean."""
        mean, _ = self.encode(self.features(batch))
        return self.critic(mean)

    def adversary_loss(self, z_e: torch.Tensor, z_p: torch.Tensor) -> torch.Tensor:
        """The latent adversary's loss (to descend), without the gradient penalty."""
        raise NotImplementedError

    def autoencoder_adversarial_loss(self, z_e: torch.Tensor, z_p: torch.Tensor) -> torch.Tensor:
        """The adversarial term of the auto-encoder's loss (to descend)."""
        raise NotImplementedError

    @override
    def update(
        self, expert: TransitionBatch, policy: TransitionBatch, iteration: int
    ) -> dict[str, float]:
        ae_opt, adversary_opt = self.optimizers()
        steps = []
        for expert_mb, policy_mb in self.minibatches(expert, policy):
            x_e, x_p = self.features(expert_mb), self.features(policy_mb)
            z_e, z_p = self.sample(x_e), self.sample(x_p)
            # ---- latent adversary step on fixed codes
            codes_e, codes_p = z_e.detach(), z_p.detach()
            gp = self.penalty(self.critic, codes_e, codes_p)
            adversary_loss = self.adversary_loss(codes_e, codes_p) + self.gp_weight * gp
            self.descend(adversary_opt, adversary_loss, "latent adversary loss", iteration)
            # ---- auto-encoder step
            reconstruction = self.reconstruction(x_e, z_e) + self.reconstruction(x_p, z_p)
            ae_loss = reconstruction + self.autoencoder_adversarial_loss(z_e, z_p)
            self.descend(ae_opt, ae_loss, "auto-encoder loss", iteration)
            with torch.no_grad():
                gap = self.critic(codes_e).mean() - self.critic(codes_p).mean()
            values = {
                "adversary_loss": adversary_loss,
                "gp": gp,
                "ae_loss": ae_loss,
                "reconstruction": reconstruction,
                "critic_gap": gap,
            }
            steps.append({key: float(value.detach()) for key, value in values.items()})
        return average(steps) | self.measure(expert, policy)


@register_reward("wae_gail")
class WAEGAIL(WAEReward):
    """WAE-GAIL: a latent GAN discriminator; prior and expert codes are "real"."""

    description = "WAE-GAIL (WQDIL): WAE with a latent GAN discriminator"

    @override
    def adversary_loss(self, z_e: torch.Tensor, z_p: torch.Tensor) -> torch.Tensor:
        prior = torch.randn_like(z_e)
        log_d = F.logsigmoid(self.critic(prior)) + F.logsigmoid(self.critic(z_e))
        log_not_d = F.logsigmoid(-self.critic(z_p))  # log(1 − σ(x)) = log σ(−x)
        return -self.regularization * (log_d + log_not_d).mean()

    @override
    def autoencoder_adversarial_loss(self, z_e: torch.Tensor, z_p: torch.Tensor) -> torch.Tensor:
        return (
            -self.regularization
            * (F.logsigmoid(self.critic(z_e)) + F.logsigmoid(self.critic(z_p))).mean()
        )


@register_reward("wae_wgail")
class WAEWGAIL(WAEReward):
    """WAE-WGAIL: a latent Wasserstein critic (gradient penalty) beside the auto-encoder.

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        adversarial_ae: add Eq. 8's λ·E[D_W(z^e) − D_W(z^π)] to the auto-encoder's loss; the
            paper's Algorithms 3–4 leave it out (decision D7, default False).
        **kwargs: :class:`WAEReward` options.
    """

    description = "WAE-WGAIL (WQDIL): WAE with a latent Wasserstein critic"

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        adversarial_ae: bool = False,
        **kwargs: Any,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures, **kwargs)
        self.adversarial_ae = adversarial_ae
        # the Wasserstein loss cannot see a constant offset of D_W: no bias on its output
        last = self.adversary[-1]
        self.adversary[-1] = torch.nn.Linear(last.in_features, 1, bias=False)
        torch.nn.init.xavier_uniform_(self.adversary[-1].weight)

    @override
    def adversary_loss(self, z_e: torch.Tensor, z_p: torch.Tensor) -> torch.Tensor:
        return -self.regularization * (self.critic(z_e).mean() - self.critic(z_p).mean())

    @override
    def autoencoder_adversarial_loss(self, z_e: torch.Tensor, z_p: torch.Tensor) -> torch.Tensor:
        if not self.adversarial_ae:
            return torch.zeros(())
        return self.regularization * (self.critic(z_e).mean() - self.critic(z_p).mean())


@register_reward("mcwae_wgail")
class MCWAEWGAIL(MeasureConditioned, WAEWGAIL):
    """mCWAE-WGAIL: WAE-WGAIL on x = (s, a, δ(s)); with the bonus, WQDIL's reward.

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        use_measures: measure conditioning, on by default: this is what "mC" names.
        **kwargs: :class:`WAEWGAIL` options.
    """

    description = "mCWAE-WGAIL (WQDIL): measure-conditioned WAE-WGAIL, the paper's method"


@register_reward("mcwae_gail")
class MCWAEGAIL(MeasureConditioned, WAEGAIL):
    """mCWAE-GAIL: WAE-GAIL on x = (s, a, δ(s)) (the paper's ablation).

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        use_measures: measure conditioning, on by default.
        **kwargs: :class:`WAEReward` options.
    """

    description = "mCWAE-GAIL (WQDIL ablation): measure-conditioned WAE-GAIL"
