"""Sampling the actions of P policies, step after step of a rollout.

:class:`PolicySampler` is the per-step policy inference of every rollout and evaluation
(:mod:`qdil.rl.collect`): the N observations are cut into P contiguous blocks, one per
policy, normalised with the policy's statistics, and the Gaussian policy's actions and
log-likelihoods computed. On the CPU every row is computed alone
(:mod:`qdil.rl.inference`), so its bits do not depend on the batch; on a device, with
torch's batched products.
"""

from __future__ import annotations

import math

import torch

from qdil.rl.inference import RowwisePolicies
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from qdil.timing import POLICY_INFERENCE, timed

# log √(2π), the Gaussian's log-normaliser per dimension, exactly as torch's Normal writes it
_LOG_SQRT_2PI = math.log(math.sqrt(2 * math.pi))


class PolicySampler:
    """Samples actions of P policies step after step, their statistics and σ held fixed.

    Rollouts call the policies once per env step, so everything that does not change
    between steps is computed once here: the float32 observation mean and scale, σ and
    2σ². A step is then the normalisation, the MLP and a few elementwise ops, with none
    of ``torch.distributions.Normal``'s object and validation overhead.

    On the CPU the step is :class:`~qdil.rl.inference.RowwisePolicies`: each row alone, in
    one fixed order, so a row's outputs are the same bits in a batch of any size (a remote
    worker's shard, an evaluation batch, a single rendered episode), with any thread count.
    On a device the arithmetic is :meth:`RunningMeanStd.normalize`'s and
    ``Normal.log_prob``'s op for op, with torch's batched products, whose last bits follow
    the batch's shape there.

    Args:
        actor: P policies; their parameters must not change while the sampler is used.
        stats: their observation statistics (frozen).
        obs_clip: bound of normalised observations (``None``: no clipping).
    """

    def __init__(
        self, actor: VectorizedActor, stats: RunningMeanStd, obs_clip: float | None
    ) -> None:
        self.actor = actor
        self.num_policies = actor.num_models
        self.obs_clip = obs_clip
        with torch.no_grad():
            self.obs_mean = stats.mean.to(torch.float32).unsqueeze(1)
            self.obs_scale = torch.sqrt(stats.var + 1e-8).to(torch.float32).unsqueeze(1)
            self.std = actor.log_std.exp().unsqueeze(1)  # (P, 1, A)
            self.two_var = 2 * self.std**2
            self.log_scale = self.std.log()
            self.operands = actor.operands()
        self.rowwise = None
        if self.std.device.type == "cpu":
            self.rowwise = RowwisePolicies(
                actor.sizes,
                self.operands,
                self.obs_mean,
                self.obs_scale,
                self.std,
                self.two_var,
                self.log_scale,
                obs_clip,
            )

    @timed(POLICY_INFERENCE)
    def sample(
        self,
        obs: torch.Tensor,
        generator: torch.Generator | None,
        deterministic: bool = False,
        log_probs: bool = True,
        noise: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """Sample actions for N observations, N/P consecutive ones per policy.

        Args:
            obs: (N, obs_dim) float32 raw observations, N divisible by P.
            generator: random source of the Gaussian noise.
            deterministic: take the mean action (draws no noise).
            log_probs: compute the log-likelihoods (``None`` in their place otherwise).
            noise: (N, A) standard normal noise drawn elsewhere (a remote worker replays
                the head's stream); ``generator`` is then not used.

        Returns:
            ``(norm_obs, actions, log_probs)``: (N, obs_dim), (N, A) unclipped, (N,).
        """
        n = obs.shape[0]
        if self.rowwise is not None:
            if not deterministic and noise is None:
                noise = torch.randn((n, self.std.shape[-1]), generator=generator)
            return self.rowwise.sample(obs, None if deterministic else noise, log_probs)
        with torch.no_grad():
            x = obs.reshape(self.num_policies, n // self.num_policies, obs.shape[1])
            norm = (x - self.obs_mean) / self.obs_scale
            if self.obs_clip is not None:
                norm = norm.clamp(-self.obs_clip, self.obs_clip)
            mean = self.actor.mlp(norm, self.operands)
            if deterministic:
                actions = mean
            else:
                if noise is None:
                    noise = torch.randn(mean.shape, generator=generator, device=mean.device)
                actions = mean + self.std * noise.reshape(mean.shape)
            logp = None
            if log_probs:
                logp = (
                    -((actions - mean) ** 2) / self.two_var - self.log_scale - _LOG_SQRT_2PI
                ).sum(-1)
        return (
            norm.reshape(obs.shape),
            actions.reshape(n, -1),
            None if logp is None else logp.reshape(-1),
        )


def act(
    actor: VectorizedActor,
    stats: RunningMeanStd,
    obs: torch.Tensor,
    obs_clip: float,
    generator: torch.Generator | None,
    deterministic: bool = False,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Sample actions of P policies for N observations (one step of a :class:`PolicySampler`).

    Args:
        actor: P policies.
        stats: their observation statistics.
        obs: (N, obs_dim) raw observations, N divisible by P.
        obs_clip: bound of normalised observations.
        generator: random source of the Gaussian noise.
        deterministic: take the mean action.

    Returns:
        ``(norm_obs, actions, log_probs)``: (N, obs_dim), (N, A) unclipped, (N,).
    """
    norm, actions, log_probs = PolicySampler(actor, stats, obs_clip).sample(
        obs, generator, deterministic
    )
    assert log_probs is not None
    return norm, actions, log_probs
