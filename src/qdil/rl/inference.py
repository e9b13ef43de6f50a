"""Policy inference on the CPU whose every row is computed alone, in one fixed order.

A row's action, likelihood and normalised observation are the same bits whether it is
computed alone or inside a batch of any size, with any thread count, on any x86 or ARM CPU:
each output is a sequence of IEEE float32 additions and multiplications in an order that
only the layer sizes fix (``tanh`` in float64, rounded once). Rollouts and evaluations use
it on the CPU (:class:`~qdil.rl.sampler.PolicySampler`), so a run's numbers do not depend
on how its simulations are split among workers or evaluation batches. Why not torch's
``baddbmm``: docs/concepts/reproducibility.md.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import prange

from qdil.envs.mujoco_c import cached_njit

ROWS = 4
"""Rows of one policy that a kernel task runs through a layer together (sharing its weights)."""

_F4, _F8 = np.float32, np.float64
# log √(2π) in float32, the Gaussian's log-normaliser per dimension
_LOG_SQRT_2PI = _F4(math.log(math.sqrt(2 * math.pi)))
# 1/k!, k = 13 .. 2: exp's Taylor coefficients, highest first
_EXP_TAYLOR = tuple(_F8(1.0 / math.factorial(k)) for k in range(13, 1, -1))
# tanh's odd Taylor series below x⁹ (62/2835 x⁹ is the leading term), highest first
_TANH_SERIES = (_F8(-17.0 / 315.0), _F8(2.0 / 15.0), _F8(-1.0 / 3.0), _F8(1.0))


@cached_njit(inline="always")
def tanh(v):  # pragma: no cover - numba
    """float32 tanh through float64: 0.5 ulp but for rare near-ties, from + and × alone.

    exp(-2|x|) is exp(-|x|/16)³² (a Taylor polynomial of degree 13 on |x|/16 ≤ 0.6, then
    five squarings: relative error about 1e-14); near zero an odd Taylor series takes
    over, past 9.1 the float32 result is ±1. No library call, so the loop vectorises and
    gives the same bits on every CPU.
    """
    x = _F8(v)
    a = abs(x)
    r = max(-a * _F8(0.0625), _F8(-0.6))
    e = _F8(0.0)
    for c in _EXP_TAYLOR:
        e = e * r + c
    e = (e * r + _F8(1.0)) * r + _F8(1.0)
    e = e * e
    e = e * e
    e = e * e
    e = e * e
    e = e * e
    t = (_F8(1.0) - e) / (_F8(1.0) + e)
    s = a * a
    series = _F8(62.0 / 2835.0)
    for c in _TANH_SERIES:
        series = series * s + c
    series = series * a
    if a < _F8(0.015625):
        t = series
    if a > _F8(9.1):
        t = _F8(1.0)
    return _F4(math.copysign(t, x))


@cached_njit(inline="always")
def _layer(w, b, n_in, n_out, x, y, rows, hidden):  # pragma: no cover - numba
    """y[r, :n_out] = act(Σ_k x[r, k] w[k, :] + b) for r < rows, k in order; w is (in, out)."""
    for r in range(rows):
        for j in range(n_out):
            y[r, j] = _F4(0.0)
    for k in range(n_in):
        w_k = w[k * n_out : (k + 1) * n_out]
        if rows == ROWS:  # the four rows share each weight load; the same + and × per row
            y0, y1, y2, y3 = y[0], y[1], y[2], y[3]
            x0, x1, x2, x3 = x[0, k], x[1, k], x[2, k], x[3, k]
            for j in range(n_out):
                y0[j] += x0 * w_k[j]
                y1[j] += x1 * w_k[j]
                y2[j] += x2 * w_k[j]
                y3[j] += x3 * w_k[j]
        else:
            y0, x0 = y[0], x[0, k]
            for j in range(n_out):
                y0[j] += x0 * w_k[j]
    for r in range(rows):
        y_r = y[r]
        for j in range(n_out):
            y_r[j] += b[j]
        if hidden:
            for j in range(n_out):
                y_r[j] = tanh(y_r[j])


@cached_njit(nogil=True, parallel=True)
def _sample(
    obs, block, mean, scale, clip, params, w_at, b_at, sizes, noise, std, two_var, log_scale,
    norm_out, action_out, logp_out, logp,
):  # fmt: skip  # pragma: no cover - numba
    """Every row of ``obs``: normalise, run its policy's MLP, sample and score the action.

    Row i belongs to policy ``i // block``. Tasks are ``ROWS`` rows of one policy, then its
    remaining rows one by one; every row gets the same operations in the same order.
    """
    n, layers, width = obs.shape[0], sizes.shape[0] - 1, sizes.max()
    num_actions = sizes[layers]
    policies = n // block
    per_policy = block // ROWS + block % ROWS
    for task in prange(policies * per_policy):
        p, i = task // per_policy, task % per_policy
        if i < block // ROWS:
            first, rows = p * block + i * ROWS, ROWS
        else:
            first, rows = p * block + (block // ROWS) * ROWS + i - block // ROWS, 1
        h = np.empty((2, ROWS, width), dtype=_F4)
        for r in range(rows):
            for k in range(sizes[0]):
                v = (obs[first + r, k] - mean[p, k]) / scale[p, k]
                if v < -clip:
                    v = -clip
                elif v > clip:
                    v = clip
                h[0, r, k] = norm_out[first + r, k] = v
        for layer in range(layers):
            n_in, n_out = sizes[layer], sizes[layer + 1]
            w = params[p, w_at[layer] : w_at[layer] + n_in * n_out]
            b = params[p, b_at[layer] : b_at[layer] + n_out]
            _layer(w, b, n_in, n_out, h[layer % 2], h[1 - layer % 2], rows, layer < layers - 1)
        out = h[layers % 2]
        for r in range(rows):
            total = _F4(0.0)
            for a in range(num_actions):
                m = out[r, a]
                action = m if noise.shape[0] == 0 else m + std[p, a] * noise[first + r, a]
                action_out[first + r, a] = action
                d = action - m
                total += -(d * d) / two_var[p, a] - log_scale[p, a] - _LOG_SQRT_2PI
            if logp:
                logp_out[first + r] = total


class RowwisePolicies:
    """P Gaussian MLP policies, their statistics and σ frozen, acting row by row on the CPU.

    Args:
        sizes: layer widths, observation first, actions last.
        operands: per layer, the (P, 1, out) bias and (P, in, out) weightᵀ
            (``VectorizedActor.operands``).
        obs_mean: (P, 1, obs_dim) float32 observation means.
        obs_scale: (P, 1, obs_dim) float32 observation scales (√(var + ε)).
        std: (P, 1, A) float32 action standard deviations σ.
        two_var: (P, 1, A) 2σ².
        log_scale: (P, 1, A) log σ.
        obs_clip: bound of normalised observations (``None``: no clipping).
    """

    def __init__(
        self,
        sizes: list[int],
        operands: list[tuple[torch.Tensor, torch.Tensor]],
        obs_mean: torch.Tensor,
        obs_scale: torch.Tensor,
        std: torch.Tensor,
        two_var: torch.Tensor,
        log_scale: torch.Tensor,
        obs_clip: float | None,
    ) -> None:
        num = std.shape[0]
        parts, w_at, b_at, offset = [], [], [], 0
        for bias, weight_t in operands:
            # (in, out) rows: the kernel's inner loop runs over contiguous outputs
            parts += [weight_t.detach().reshape(num, -1), bias.detach().reshape(num, -1)]
            w_at.append(offset)
            b_at.append(offset := offset + parts[-2].shape[1])
            offset += parts[-1].shape[1]
        self.num_policies = num
        self.params = torch.cat(parts, 1).to(torch.float32).contiguous().numpy()
        self.w_at, self.b_at = np.array(w_at, np.int64), np.array(b_at, np.int64)
        self.sizes = np.array(sizes, np.int64)
        self.mean, self.scale = _array(obs_mean.squeeze(1)), _array(obs_scale.squeeze(1))
        self.std, self.two_var = _array(std.squeeze(1)), _array(two_var.squeeze(1))
        self.log_scale = _array(log_scale.squeeze(1))
        self.clip = _F4(np.inf if obs_clip is None else obs_clip)
        self._no_noise = np.zeros((0, self.std.shape[1]), _F4)

    def sample(
        self, obs: torch.Tensor, noise: torch.Tensor | None, log_probs: bool
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """Act on N observations, N/P consecutive ones per policy.

        Args:
            obs: (N, obs_dim) float32 raw observations.
            noise: (N, A) standard normal noise (``None``: the mean actions).
            log_probs: compute the log-likelihoods.

        Returns:
            ``(norm_obs, actions, log_probs)``: (N, obs_dim), (N, A) unclipped, (N,) or
            ``None``.

        Raises:
            ValueError: N is not a multiple of P.
        """
        n, num_actions = obs.shape[0], self.std.shape[1]
        if n % self.num_policies:
            raise ValueError(f"{n} observations cannot be split among {self.num_policies} policies")
        norm = torch.empty(obs.shape, dtype=torch.float32)
        actions = torch.empty((n, num_actions), dtype=torch.float32)
        logp = torch.empty(n if log_probs else 0, dtype=torch.float32)
        _sample(
            _array(obs),
            n // self.num_policies,
            self.mean,
            self.scale,
            self.clip,
            self.params,
            self.w_at,
            self.b_at,
            self.sizes,
            self._no_noise if noise is None else _array(noise.reshape(n, num_actions)),
            self.std,
            self.two_var,
            self.log_scale,
            norm.numpy(),
            actions.numpy(),
            logp.numpy(),
            log_probs,
        )
        return norm, actions, logp if log_probs else None


def _array(x: torch.Tensor) -> np.ndarray:
    """A C-contiguous float32 numpy view (or copy) of a CPU tensor."""
    return np.ascontiguousarray(x.detach().to(torch.float32).numpy())
