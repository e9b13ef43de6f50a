"""Generalised advantage estimation (Schulman et al., 2016), as a pure function."""

from __future__ import annotations

import torch


def compute_gae(
    rewards: torch.Tensor,
    values: torch.Tensor,
    next_values: torch.Tensor,
    dones: torch.Tensor,
    terminated: torch.Tensor,
    gamma: float,
    gae_lambda: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Advantages and value targets of time-major rollouts.

    δ_t = r_t + γ (1 − terminated_t) V(s_{t+1}) − V(s_t) and A_t = δ_t + γλ (1 − done_t) A_{t+1}.
    ``next_values[t]`` is V of the observation after step t (the final observation where an
    episode ended), so a time-limit truncation bootstraps from the state it stopped in. To
    treat truncations as terminal, as PPGA's code does, pass ``terminated = dones``.

    Args:
        rewards: (T, ...) rewards r_t.
        values: (T, ...) V(s_t).
        next_values: (T, ...) V(s_{t+1}).
        dones: (T, ...) 1.0 where the episode ended at step t.
        terminated: (T, ...) 1.0 where it ended by termination.
        gamma: discount γ.
        gae_lambda: GAE λ.

    Returns:
        ``(advantages, returns)``, both (T, ...), with returns = advantages + values.
    """
    deltas = rewards + gamma * (1.0 - terminated) * next_values - values
    advantages = torch.zeros_like(rewards)
    running = torch.zeros_like(rewards[0])
    for t in reversed(range(rewards.shape[0])):
        running = deltas[t] + gamma * gae_lambda * (1.0 - dones[t]) * running
        advantages[t] = running
    return advantages, advantages + values
