"""``diffail``: Diffusion Adversarial Imitation Learning (Wang et al., AAAI 2024).

https://arxiv.org/abs/2312.06348. The discriminator is an unconditional diffusion model of
x = (s, a[, δ(s)]): with the diffusion loss L(x) = E_{t,ε} mean_j (ε_φ(x_t, t) − ε)_j²,

    D(x) = exp(−L(x)) ∈ (0, 1],

near 1 where the model denoises x well (expert-like). It is trained as GAIL's discriminator,
binary cross-entropy with expert label 1 and policy label 0, on one (t, ε) draw per sample:
loss = E_e[L(x)] − E_π[log(1 − exp(−L(x)))] + w_gp·GP. The reward is GAIL's −log(1 − D + 1e-8).

For the reward, D is estimated as both public codes (ML-Group-SDU/DiffAIL, vanzll/EBC) do:
the mean over K timesteps and the d coordinates of exp(−e_{t,j}), e = (ε_φ(x_t, t) − ε)²
(``reward_estimate: elementwise``, K = T by default); ``loss`` uses the paper's exp(−L) with
L averaged over the same draws instead. Unlike the public codes, the K noise draws of the
reward are fixed when the model is built (common random numbers, saved in checkpoints), so
the reward is a function of x: a resumed run scores transitions as the original would.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import torch
from typing_extensions import override

from qdil.data import TransitionBatch
from qdil.rewards import register_reward
from qdil.rewards.adversarial import AdversarialReward, average
from qdil.rewards.nets import gradient_penalty
from qdil_diffail.diffusion import NoisePredictor, linear_schedule, squared_errors

# rows of x_t (reward transitions × timesteps) per forward pass of the reward: bounds memory
# (d ≈ 400 for Humanoid: ~50 MB a chunk) without slowing the small tasks
REWARD_CHUNK = 32768


def discriminator_loss(loss_expert: torch.Tensor, loss_policy: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy of D = exp(−L) with expert label 1 and policy label 0.

    −log D = L for the expert; −log(1 − e^{−L}) for the policy, through expm1 for precision,
    with L ≥ 1e-8 capping that term near 18.4 (where the policy denoises perfectly).

    Args:
        loss_expert: (B,) diffusion losses L of expert inputs.
        loss_policy: (B,) diffusion losses L of policy inputs.

    Returns:
        The scalar mean over expert inputs plus the mean over policy inputs.
    """
    policy_term = -torch.log(-torch.expm1(-loss_policy.clamp_min(1e-8)))
    return loss_expert.mean() + policy_term.mean()


@register_reward("diffail")
class DiffAIL(AdversarialReward):
    """DiffAIL: the diffusion loss as discriminator, D = exp(−L); reward −log(1 − D).

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        hidden: hidden widths of the noise predictor (public code: (100, 100, 100), Mish).
        time_dim: size of the timestep embedding (public code: 16).
        timesteps: T, diffusion steps (public code and paper: 100).
        beta_start: β_1 of the linear schedule (DDPM and public code: 1e-4).
        beta_end: β_T of the linear schedule (DDPM and public code: 0.02).
        reward_timesteps: K, timesteps the reward averages over, spread evenly over 0..T−1;
            ``None`` uses all T (public code). Smaller K makes the reward K/T as costly.
        reward_estimate: ``elementwise``: D = mean_{t,j} exp(−e_{t,j}) (public code);
            ``loss``: D = exp(−mean_{t,j} e_{t,j}) (the paper's exp(−L)).
        **kwargs: :class:`~qdil.rewards.adversarial.AdversarialReward` options
            (use_measures, learning_rate, batch_size, epochs, gp_weight).
    """

    description = "DiffAIL (Wang et al. 2024): diffusion-loss discriminator D=exp(-L), -log(1-D)"

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        hidden: Sequence[int] = (100, 100, 100),
        time_dim: int = 16,
        timesteps: int = 100,
        beta_start: float = 1e-4,
        beta_end: float = 0.02,
        reward_timesteps: int | None = None,
        reward_estimate: Literal["elementwise", "loss"] = "elementwise",
        **kwargs: Any,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures, **kwargs)
        if timesteps < 1:
            raise ValueError(f"DiffAIL: timesteps must be positive, got {timesteps}")
        if not 0.0 < beta_start <= beta_end < 1.0:
            raise ValueError(
                f"DiffAIL: need 0 < beta_start <= beta_end < 1, got {beta_start}, {beta_end}"
            )
        count = timesteps if reward_timesteps is None else reward_timesteps
        if not 1 <= count <= timesteps:
            raise ValueError(
                f"DiffAIL: reward_timesteps must lie in 1..timesteps ({timesteps}) or be null, "
                f"got {reward_timesteps}"
            )
        self.timesteps = timesteps
        self.reward_estimate = reward_estimate
        self.denoiser = NoisePredictor(self.input_dim, hidden, time_dim)
        self.register_buffer("alpha_bar", linear_schedule(timesteps, beta_start, beta_end))
        # the midpoints of K equal slices of 0..T-1: all of them when K = T
        slices = (torch.arange(count) + 0.5) * timesteps / count
        self.register_buffer("reward_t", slices.long())
        self.register_buffer("reward_noise", torch.randn(count, self.input_dim))

    def diffusion_loss(self, x: torch.Tensor) -> torch.Tensor:
        """(B,) L(x): mean squared noise-prediction error at one fresh (t, ε) per input."""
        t = torch.randint(self.timesteps, (x.shape[0],))
        return squared_errors(self.denoiser, self.alpha_bar, x, t, torch.randn_like(x)).mean(-1)

    def discriminator(self, x: torch.Tensor) -> torch.Tensor:
        """(B,) D(x) = exp(−L(x)) of inputs x (B, input_dim), on one fresh (t, ε) each."""
        return torch.exp(-self.diffusion_loss(x))

    def reward_discriminator(self, x: torch.Tensor) -> torch.Tensor:
        """(B,) D(x) of the reward: over the fixed K timesteps and noise draws.

        Args:
            x: (B, input_dim) inputs.
        """
        k, d = self.reward_noise.shape
        rows = max(1, REWARD_CHUNK // k)
        out = []
        for chunk in x.split(rows):
            b = chunk.shape[0]
            x0 = chunk.unsqueeze(1).expand(b, k, d).reshape(b * k, d)
            t = self.reward_t.repeat(b)
            noise = self.reward_noise.repeat(b, 1)
            errors = squared_errors(self.denoiser, self.alpha_bar, x0, t, noise).reshape(b, k, d)
            if self.reward_estimate == "loss":
                out.append(torch.exp(-errors.mean((1, 2))))
            else:
                out.append(torch.exp(-errors).mean((1, 2)))
        return torch.cat(out) if out else x.new_zeros(0)

    @override
    def configure_optimizers(self) -> torch.optim.Optimizer:
        return torch.optim.Adam(self.parameters(), lr=self.learning_rate)

    @override
    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        d = self.reward_discriminator(self.features(batch))
        return -torch.log(1.0 - d + 1e-8)

    @override
    def update(
        self, expert: TransitionBatch, policy: TransitionBatch, iteration: int
    ) -> dict[str, float]:
        optimizer = self.optimizers()
        steps = []
        for expert_mb, policy_mb in self.minibatches(expert, policy):
            x_e, x_p = self.features(expert_mb), self.features(policy_mb)
            loss_e, loss_p = self.diffusion_loss(x_e), self.diffusion_loss(x_p)
            gp = (
                gradient_penalty(self.discriminator, x_e, x_p)
                if self.gp_weight
                else torch.zeros(())
            )
            loss = discriminator_loss(loss_e, loss_p) + self.gp_weight * gp
            self.descend(optimizer, loss, "discriminator loss", iteration)
            d_e, d_p = torch.exp(-loss_e.detach()), torch.exp(-loss_p.detach())
            steps.append(
                {
                    "loss": float(loss.detach()),
                    "gp": float(gp.detach()),
                    "expert_d": float(d_e.mean()),
                    "policy_d": float(d_p.mean()),
                    "expert_acc": float((d_e > 0.5).float().mean()),
                    "policy_acc": float((d_p < 0.5).float().mean()),
                }
            )
        return average(steps)
