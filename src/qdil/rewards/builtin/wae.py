"""The WAE family of WQDIL (Yu et al., AAMAS 2025, https://arxiv.org/abs/2411.06965).

:class:`WAEReward`: a Wasserstein auto-encoder embeds (s, a), or (s, a, δ(s)) with measure
conditioning, and a latent adversary scores the codes. :class:`WAEGAIL`, :class:`WAEWGAIL`,
:class:`MCWAEWGAIL` and :class:`MCWAEGAIL` register ``wae_gail``, ``wae_wgail``,
``mcwae_wgail`` and ``mcwae_gail``. Equations, decisions D6 and D7 and the choices the paper
leaves open: docs/rewards/wae_wgail.md and docs/rewards/wae_gail.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import torch
import torch.nn.functional as F
from typing_extensions import override

from qdil.data import TransitionBatch
from qdil.reductions import mean_over, std_over
from qdil.rewards.adversarial import AdversarialReward, MeasureConditioned, average
from qdil.rewards.nets import gail_reward, mlp
from qdil.rewards.registry import register_reward

CALIBRATION_LOGIT = 2.0
"""|ℓ| of the expert's and the policy's mean critic values under ``calibrated``."""


def calibrated_logit(
    score: torch.Tensor, expert_mean: float, policy_mean: float, min_gap: float
) -> torch.Tensor:
    """Map critic values onto a logit fixed by the critic's expert and policy means.

    ℓ = 2·CALIBRATION_LOGIT·(D − (μ_e + μ_π)/2) / max(μ_e − μ_π, min_gap): μ_e maps to
    +CALIBRATION_LOGIT, μ_π to −CALIBRATION_LOGIT, the midpoint to 0. A critic that no longer
    separates the two (gap below ``min_gap``) gives flatter logits instead of amplified noise.

    Args:
        score: (B,) critic values D(z̄).
        expert_mean: μ_e, the critic's mean on expert inputs.
        policy_mean: μ_π, the critic's mean on policy inputs.
        min_gap: smallest gap used as the scale (> 0).

    Returns:
        (B,) logits.
    """
    gap = max(expert_mean - policy_mean, min_gap)
    return 2.0 * CALIBRATION_LOGIT * (score - 0.5 * (expert_mean + policy_mean)) / gap


def standardized_logit(score: torch.Tensor, policy_mean: float, policy_std: float) -> torch.Tensor:
    """Map critic values onto a logit standardised on the policy's own data.

    ℓ = (D − μ_π) / σ_π: the policy's mean maps to 0 (r = log 2 under GAIL's transform) and
    every σ_π of critic value above it adds one logit unit, however far the expert's mean
    lies. Unlike :func:`calibrated_logit`, a critic that separates expert and policy well
    (a large gap) does not flatten the differences between policy transitions.

    Args:
        score: (B,) critic values D(z̄).
        policy_mean: μ_π, the critic's mean on policy inputs.
        policy_std: σ_π, its standard deviation there (> 0).

    Returns:
        (B,) logits.
    """
    return (score - policy_mean) / policy_std


class WAEReward(AdversarialReward):
    """Shared machinery of the WAE reward models (not registered itself).

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        latent_dim: size of z (the paper does not give it). 32 (Walker2d's and
            HalfCheetah's inputs have 25 numbers) keeps the action in the code: with 8 the
            critic hardly tells a good action from a bad one in the same state
            (``benchmarks/reward_actions.py``, docs/rewards/balance.md).
        hidden: widths of encoder, decoder and latent adversary (the paper: (100, 100)).
        regularization: λ (the paper: 1).
        reward_type: ``gail`` (−log(1 − σ(D(z̄)) + 1e-8), default), ``calibrated`` (the
            GAIL form of :func:`calibrated_logit`), ``standardized`` (the GAIL form of
            :func:`standardized_logit`), ``standardized_logit`` (that logit ℓ itself, DAC's
            log D − log(1 − D): signed, so an absorbing state can be worth less than
            staying alive), ``critic`` (D(z̄)) or ``sigmoid`` (σ(D(z̄))).
        min_gap: smallest expert–policy critic gap that ``calibrated`` divides by, and
            (over 4) the smallest policy spread that ``standardized`` divides by.
        calibration_samples: policy transitions (at most) the calibration scores after
            each update; all expert transitions are scored.
        **kwargs: :class:`~qdil.rewards.adversarial.AdversarialReward` options.
    """

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        latent_dim: int = 32,
        hidden: Sequence[int] = (100, 100),
        regularization: float = 1.0,
        reward_type: Literal[
            "gail", "calibrated", "standardized", "standardized_logit", "critic", "sigmoid"
        ] = "gail",
        min_gap: float = 1.0,
        calibration_samples: int = 8192,
        **kwargs: Any,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures, **kwargs)
        if min_gap <= 0:
            raise ValueError(f"{type(self).__name__}: min_gap must be > 0, got {min_gap}")
        if calibration_samples < 1:
            raise ValueError(
                f"{type(self).__name__}: calibration_samples must be positive, "
                f"got {calibration_samples}"
            )
        self.latent_dim = latent_dim
        self.regularization = regularization
        self.reward_type = reward_type
        self.min_gap = min_gap
        self.calibration_samples = calibration_samples
        # μ_e and μ_π of the last update (checkpointed); the initial pair (+2, −2) makes
        # ℓ = D before the first update, the untrained critic's own value
        self.register_buffer(
            "critic_means",
            torch.tensor([CALIBRATION_LOGIT, -CALIBRATION_LOGIT], dtype=torch.float64),
        )
        # σ_π of the last update, for ``standardized`` (checkpointed; 1 before the first)
        self.register_buffer("critic_policy_std", torch.ones((), dtype=torch.float64))
        self._register_load_state_dict_pre_hook(_default_policy_std)
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

    def score(self, batch: TransitionBatch) -> torch.Tensor:
        """(B,) critic values D(z̄) at the encoder mean."""
        mean, _ = self.encode(self.features(batch))
        return self.critic(mean)

    @override
    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        return self.transform(self.score(batch))

    def transform(self, score: torch.Tensor) -> torch.Tensor:
        """(B,) rewards from critic values, by ``reward_type``."""
        if self.reward_type == "critic":
            return score
        if self.reward_type == "sigmoid":
            return torch.sigmoid(score)
        if self.reward_type == "calibrated":
            expert_mean, policy_mean = self.critic_means.tolist()
            score = calibrated_logit(score, expert_mean, policy_mean, self.min_gap)
        elif self.reward_type in ("standardized", "standardized_logit"):
            policy_std = max(float(self.critic_policy_std), self.min_gap / 4)
            score = standardized_logit(score, float(self.critic_means[1]), policy_std)
            if self.reward_type == "standardized_logit":
                return score
        return gail_reward(score)

    @torch.no_grad()
    def calibrate(self, expert: TransitionBatch, policy: TransitionBatch) -> dict[str, float]:
        """Store the critic's means on expert and policy inputs (at z̄) for ``calibrated``.

        Args:
            expert: every expert transition.
            policy: the iteration's policy transitions (a random subset is scored).

        Returns:
            μ_e, μ_π, the critic's standard deviation on either side and the mean
            calibrated reward on either side, to log.
        """
        if len(policy) > self.calibration_samples:
            policy = policy[torch.randperm(len(policy))[: self.calibration_samples]]
        scores = self.score(expert), self.score(policy)
        # every expert transition: from 32,768 of them torch's mean would split by thread
        means = [float(mean_over(s, 0)) for s in scores]
        self.critic_means.copy_(torch.tensor(means, dtype=torch.float64))
        if len(scores[1]) > 1:
            self.critic_policy_std.fill_(float(std_over(scores[1], 0)))
        metrics = {"critic_expert": means[0], "critic_policy": means[1]}
        # the spread within each side, against the gap: how much the reward can tell policy
        # transitions apart once ``calibrated`` divides by the gap
        metrics["critic_expert_std"], metrics["critic_policy_std"] = (
            float(std_over(s, 0)) if len(s) > 1 else 0.0 for s in scores
        )
        if self.reward_type in ("calibrated", "standardized", "standardized_logit"):  # no 2nd pass
            metrics["reward_expert"] = float(self.transform(scores[0]).mean())
            metrics["reward_policy"] = float(self.transform(scores[1]).mean())
        return metrics

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
        return average(steps) | self.calibrate(expert, policy)


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


def _default_policy_std(state_dict: dict[str, Any], prefix: str, *_: Any) -> None:
    """Load checkpoints written before ``critic_policy_std`` existed (σ_π = 1 then)."""
    state_dict.setdefault(prefix + "critic_policy_std", torch.ones((), dtype=torch.float64))
