"""The WAE family of WQDIL (Yu et al., AAMAS 2025, https://arxiv.org/abs/2411.06965).

A Wasserstein auto-encoder (Tolstikhin et al., 2018) with encoder Q_φ(z | x) and decoder
G_ψ(z) embeds x = (s, a), or x = (s, a, δ(s)) with measure conditioning ("mC"); a latent
adversary separates expert codes z^e from policy codes z^π. Per gradient step (the paper's
appendix algorithms, with n the minibatch size and f_c(x, y) = ‖x − y‖²):

- ``wae_gail`` (Alg. "WAE-GAIL"): D ascends (λ/n) Σ [log D(z̃) + log D(z^e) + log(1 − D(z^π))]
  with z̃ ~ N(0, I); Q and G descend (1/n) Σ [f_c(x^e, G(z^e)) + f_c(x^π, G(z^π))
  − λ (log D(z^e) + log D(z^π))].
- ``wae_wgail`` (Alg. "WAE-WGAIL"): a 1-Lipschitz critic D_W (gradient penalty) ascends
  (λ/n) Σ [D_W(z^e) − D_W(z^π)]; Q and G descend the reconstruction terms only (decision
  D7; ``adversarial_ae=True`` adds Eq. 8's λ E[D_W(z^e) − D_W(z^π)]).
- ``mcwae_wgail`` (Alg. "mCWAE-WGAIL", WQDIL's reward) and ``mcwae_gail``: the same on
  x = (s, a, δ(s)).

Reward (decision D6): r = −log(1 − σ(D(z̄)) + 1e-8) at the encoder mean z̄ = E[Q_φ(z | x)],
the GAIL form the paper routes every reward through; ``reward_type`` offers the raw critic
value and σ(D(z̄)). Unspecified by the paper, chosen here and documented: encoder, decoder
and adversary widths (100, 100), latent size 8, a Gaussian encoder.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import torch
import torch.nn.functional as F
from typing_extensions import override

from qdil.data import TransitionBatch
from qdil.rewards.adversarial import AdversarialReward, average
from qdil.rewards.nets import gail_reward, gradient_penalty, mlp
from qdil.rewards.registry import register_reward


class WAEReward(AdversarialReward):
    """Shared machinery of the WAE reward models (not registered itself).

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        latent_dim: size of z.
        hidden: widths of encoder, decoder and latent adversary (the paper: (100, 100)).
        regularization: λ (the paper: 1).
        reward_type: ``gail`` (−log(1 − σ(D(z̄)) + 1e-8), default), ``critic`` (D(z̄)) or
            ``sigmoid`` (σ(D(z̄))).
        **kwargs: :class:`~qdil.rewards.adversarial.AdversarialReward` options.
    """

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        latent_dim: int = 8,
        hidden: Sequence[int] = (100, 100),
        regularization: float = 1.0,
        reward_type: Literal["gail", "critic", "sigmoid"] = "gail",
        **kwargs: Any,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures, **kwargs)
        self.latent_dim = latent_dim
        self.regularization = regularization
        self.reward_type = reward_type
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
    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        mean, _ = self.encode(self.features(batch))
        score = self.critic(mean)
        if self.reward_type == "critic":
            return score
        if self.reward_type == "sigmoid":
            return torch.sigmoid(score)
        return gail_reward(score)

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
            gp = torch.zeros(())
            if self.gp_weight:
                gp = gradient_penalty(self.critic, codes_e, codes_p)
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
        return average(steps)


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
class MCWAEWGAIL(WAEWGAIL):
    """mCWAE-WGAIL: WAE-WGAIL on x = (s, a, δ(s)); with the bonus, WQDIL's reward.

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        use_measures: measure conditioning, on by default: this is what "mC" names.
        **kwargs: :class:`WAEWGAIL` options.
    """

    description = "mCWAE-WGAIL (WQDIL): measure-conditioned WAE-WGAIL, the paper's method"

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        use_measures: bool = True,
        **kwargs: Any,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures, use_measures=use_measures, **kwargs)


@register_reward("mcwae_gail")
class MCWAEGAIL(WAEGAIL):
    """mCWAE-GAIL: WAE-GAIL on x = (s, a, δ(s)) (the paper's ablation).

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        use_measures: measure conditioning, on by default.
        **kwargs: :class:`WAEReward` options.
    """

    description = "mCWAE-GAIL (WQDIL ablation): measure-conditioned WAE-GAIL"

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        use_measures: bool = True,
        **kwargs: Any,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures, use_measures=use_measures, **kwargs)
