"""One PPO iteration for P policies side by side: the core that both VPPO phases share.

:class:`~qdil.qd.vppo.VPPO` documents the choices (per-objective value normalisation,
per-minibatch advantage normalisation, clipped surrogate and value loss, per-policy gradient
clipping, early stop on the approximate KL); this module holds the update itself and the
layout helpers between time-major rollouts and per-policy batches.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from qdil.data import Rollout
from qdil.reductions import mean_over, std_over, var_over
from qdil.rl.collect import PolicyData
from qdil.rl.gae import compute_gae
from qdil.rl.networks import VectorizedActor, VectorizedCritic
from qdil.rl.normalize import RunningMeanStd
from qdil.timing import PPO_UPDATES, timed


@dataclass(frozen=True)
class PPOSettings:
    """The hyperparameters one PPO iteration reads (see :class:`~qdil.qd.vppo.VPPO`)."""

    gamma: float
    gae_lambda: float
    num_minibatches: int
    update_epochs: int
    clip_coef: float
    value_clip: float | None
    vf_coef: float
    ent_coef: float
    max_grad_norm: float
    target_kl: float | None
    normalize_returns: bool
    bootstrap_truncation: bool


def to_policies(x: torch.Tensor, num_policies: int) -> torch.Tensor:
    """(T, N, ...) -> (P, N/P · T, ...): policy i's environments, env-major."""
    steps, n = x.shape[:2]
    x = x.transpose(0, 1).reshape(num_policies, n // num_policies, steps, *x.shape[2:])
    return x.flatten(1, 2)


def from_policies(x: torch.Tensor, steps: int) -> torch.Tensor:
    """Inverse of :func:`to_policies`: (P, N/P · T, ...) -> (T, N, ...)."""
    num_policies = x.shape[0]
    x = x.reshape(num_policies, -1, steps, *x.shape[2:]).flatten(0, 1)
    return x.transpose(0, 1)


# Below this many rows CPU BLAS (MKL) takes other paths whose rows differ in the last bit
# from a large batch's (measured: 1-3 rows differ, 4 and more do not, for every obs size)
MIN_CRITIC_ROWS = 16


def next_state_values(
    critic: VectorizedCritic,
    values: torch.Tensor,
    next_obs: torch.Tensor,
    dones: torch.Tensor,
    steps: int,
) -> torch.Tensor:
    """V(s_{t+1}) of every step, reusing V(s_t) where s_{t+1} is the next step's s_t.

    While an episode goes on, the observation after step t is the one step t+1 starts from
    (the same normalised float32 vector, bit for bit), so its value is already in
    ``values``; the critic only runs on the observations after the last step and where an
    episode ended (the final observation, not the reset one). That halves the critic's
    forward work of GAE. A row of a batched product does not depend on the rows beside it
    once the batch has :data:`MIN_CRITIC_ROWS` rows, so the values equal those of a second
    pass over every ``next_obs`` bit for bit (MKL on x86 CPUs, tested; another BLAS or a GPU
    may round a row differently by batch size, and then the two differ in the last bit, as
    the same run does between two BLAS libraries).

    Args:
        critic: the P critics.
        values: (P, E·T) V(s_t), env-major as :func:`to_policies` lays them out.
        next_obs: (P, E·T, obs_dim) normalised s_{t+1}.
        dones: (T, N) 1.0 where the episode ended at step t.
        steps: T.

    Returns:
        (P, E·T) V(s_{t+1}).
    """
    num_policies, rows = values.shape
    if rows < MIN_CRITIC_ROWS:  # too few rows to share: the plain second pass
        return critic(next_obs)
    ends = to_policies(dones, num_policies).reshape(num_policies, -1, steps) > 0
    ends[:, :, -1] = True  # the rollout's last step: its next observation has no value yet
    ends = ends.reshape(num_policies, rows)
    # each policy's rows to evaluate, padded to one count by repeating its first row (a
    # duplicate row gets the same value, so the scatter below writes equal values twice)
    count = max(int(ends.sum(1).max()), MIN_CRITIC_ROWS)
    order = torch.argsort((~ends).to(torch.uint8), dim=1, stable=True)[:, :count]
    picked = torch.gather(ends, 1, order)
    index = torch.where(picked, order, order[:, :1])
    final = critic(torch.gather(next_obs, 1, index[..., None].expand(-1, -1, next_obs.shape[2])))
    shifted = torch.roll(values.reshape(num_policies, -1, steps), -1, dims=2)
    return shifted.reshape(num_policies, rows).scatter(1, index, final)


@timed(PPO_UPDATES)
def ppo_update(
    settings: PPOSettings,
    generator: torch.Generator,
    actor: VectorizedActor,
    actor_opt: torch.optim.Optimizer,
    critic: VectorizedCritic,
    critic_opt: torch.optim.Optimizer,
    return_stats: RunningMeanStd,
    rollout: Rollout,
    pdata: PolicyData,
    rewards: torch.Tensor,
) -> dict[str, float]:
    """One PPO iteration of P policies side by side: GAE on the rollout, then minibatch epochs.

    Args:
        settings: the hyperparameters.
        generator: the noise generator that shuffles the minibatches.
        actor: the P actors.
        actor_opt: their optimiser.
        critic: the P critics.
        critic_opt: their optimiser.
        return_stats: running statistics of the value targets (updated here).
        rollout: (T, N) transitions, N/P environments per policy.
        pdata: the policies' normalised observations, actions and log-probabilities.
        rewards: (T, N) rewards to maximise.

    Returns:
        Mean diagnostics: losses, entropy, approximate KL, clip fraction, explained
        variance, epochs run.
    """
    num_policies, steps = actor.num_models, rollout.num_steps
    obs = to_policies(pdata.norm_obs, num_policies)
    next_obs = to_policies(pdata.norm_next_obs, num_policies)
    # ---- values and GAE (in reward units; the critic works in normalised units)
    with torch.no_grad():
        values = critic(obs)
        next_values = next_state_values(critic, values, next_obs, rollout.dones, steps)
        if settings.normalize_returns:
            values = return_stats.denormalize(values)
            next_values = return_stats.denormalize(next_values)
        terminated = rollout.terminated if settings.bootstrap_truncation else rollout.dones
        advantages, returns = compute_gae(
            rewards,
            from_policies(values, steps),
            from_policies(next_values, steps),
            rollout.dones,
            terminated,
            settings.gamma,
            settings.gae_lambda,
        )
        returns = to_policies(returns, num_policies)
        if settings.normalize_returns:
            return_stats.update(returns)
            returns = return_stats.normalize(returns)
            values = return_stats.normalize(values)
    advantages = to_policies(advantages, num_policies)
    actions = to_policies(pdata.actions, num_policies)
    old_log_probs = to_policies(pdata.log_probs, num_policies)

    # ---- minibatch epochs
    batch = obs.shape[1]
    minibatch = max(1, batch // settings.num_minibatches)
    stats: dict[str, list[float]] = {
        k: [] for k in ("policy_loss", "value_loss", "entropy", "approx_kl", "clipfrac")
    }
    epochs = 0
    for _ in range(settings.update_epochs):
        epochs += 1
        order = torch.randperm(batch, generator=generator, device=generator.device)
        for start in range(0, batch - minibatch + 1, minibatch):
            idx = order[start : start + minibatch]
            dist = actor.distribution(obs[:, idx])
            new_log_probs = dist.log_prob(actions[:, idx]).sum(-1)
            log_ratio = new_log_probs - old_log_probs[:, idx]
            ratio = log_ratio.exp()
            # the means over a minibatch go through mean_over: with one policy (the walk) a
            # paper minibatch (48,000 rows) reduces to one number, split between threads
            with torch.no_grad():
                approx_kl = mean_over((ratio - 1) - log_ratio, 1)
                clipfrac = mean_over(((ratio - 1).abs() > settings.clip_coef).float(), 1)
            adv = advantages[:, idx]
            adv = (adv - mean_over(adv, 1, keepdim=True)) / (std_over(adv, 1, keepdim=True) + 1e-8)
            pg_rows = torch.max(
                -adv * ratio, -adv * ratio.clamp(1 - settings.clip_coef, 1 + settings.clip_coef)
            )
            new_values = critic(obs[:, idx])
            v_rows = (new_values - returns[:, idx]).square()
            if settings.value_clip is not None:
                clipped = values[:, idx] + (new_values - values[:, idx]).clamp(
                    -settings.value_clip, settings.value_clip
                )
                v_rows = torch.max(v_rows, (clipped - returns[:, idx]).square())
            entropy_rows = dist.entropy().sum(-1)
            # the losses' gradients (1/B per row) do not depend on how their means round, so
            # the loss keeps torch's means and the diagnostics below take mean_over's
            pg_loss, v_loss = pg_rows.mean(1), 0.5 * v_rows.mean(1)
            entropy = entropy_rows.mean(1)
            # a sum over policies keeps their gradients independent
            loss = (pg_loss - settings.ent_coef * entropy + settings.vf_coef * v_loss).sum()
            actor_opt.zero_grad()
            critic_opt.zero_grad()
            loss.backward()
            actor.clip_grad_norm_per_model(settings.max_grad_norm)
            critic.clip_grad_norm_per_model(settings.max_grad_norm)
            actor_opt.step()
            critic_opt.step()
            with torch.no_grad():
                step_stats = {
                    "policy_loss": mean_over(pg_rows, 1),
                    "value_loss": 0.5 * mean_over(v_rows, 1),
                    "entropy": mean_over(entropy_rows, 1),
                    "approx_kl": approx_kl,
                    "clipfrac": clipfrac,
                }
            for key, value in step_stats.items():
                stats[key].append(float(value.detach().mean()))
        if settings.target_kl is not None and float(approx_kl.mean()) > settings.target_kl:
            break
    with torch.no_grad():
        # over every sample of every policy: one output from 384,000 numbers at paper scale
        explained = 1 - var_over((returns - values).reshape(-1), 0) / (
            var_over(returns.reshape(-1), 0) + 1e-8
        )
    out = {key: float(np.mean(values_)) for key, values_ in stats.items()}
    out.update(explained_variance=float(explained), epochs=float(epochs))
    return out
