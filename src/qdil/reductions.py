"""Sums, means and variances whose bits do not depend on torch's CPU thread count.

ATen reduces a tensor to a *single* element by cutting the inputs into one range per thread
once there are at least :data:`GRAIN_SIZE` of them, and adding the ranges' partial results:
the rounding then depends on the thread count, which changes inside a qdil process (numba's
OpenMP pool, a Ray worker; see docs/concepts/reproducibility.md). A reduction with two or
more outputs is cut between outputs instead, so each output is reduced by one thread in one
pass, the same pass a single output gets with one thread.

The functions here give a single output exactly the bits torch computes for it with one
thread, whatever the thread count: a sum or mean is taken as one row of a two-row reduction
(the second row is the same memory, a stride-0 view), and a variance replays torch's
one-thread full-reduction variance (the mean, then a sequential float64 sum of squared
deviations). Any other reduction, every reduction under :data:`GRAIN_SIZE` inputs, and every
one off the CPU is torch's own call, unchanged. ``tests/test_reductions.py`` checks both
claims against torch for the shapes qdil reduces.
"""

from __future__ import annotations

import torch

GRAIN_SIZE = 32768
"""``at::internal::GRAIN_SIZE``: from this many inputs on, a single output is split by thread."""


def _lone(x: torch.Tensor, dim: int) -> bool:
    """Whether torch would reduce ``x`` over ``dim`` to one element split between threads."""
    return x.device.type == "cpu" and x.numel() >= GRAIN_SIZE and x.shape[dim] == x.numel()


def _two_rows(x: torch.Tensor) -> torch.Tensor:
    """``x`` twice along a new leading axis, without a copy."""
    return x.unsqueeze(0).expand(2, *x.shape)


def sum_over(x: torch.Tensor, dim: int, keepdim: bool = False) -> torch.Tensor:
    """``x.sum(dim, keepdim=keepdim)``, with a single output's bits as with one thread.

    Args:
        x: the tensor.
        dim: the dimension to reduce.
        keepdim: keep ``dim`` with size 1.
    """
    if not _lone(x, dim):
        return x.sum(dim, keepdim=keepdim)
    return _two_rows(x).sum(dim % x.dim() + 1, keepdim=keepdim)[0]


def mean_over(x: torch.Tensor, dim: int, keepdim: bool = False) -> torch.Tensor:
    """``x.mean(dim, keepdim=keepdim)``, with a single output's bits as with one thread.

    On the CPU torch's mean is its sum divided by the count, so the two-row sum carries over.
    """
    if not _lone(x, dim):
        return x.mean(dim, keepdim=keepdim)
    return _two_rows(x).mean(dim % x.dim() + 1, keepdim=keepdim)[0]


def var_over(
    x: torch.Tensor, dim: int, correction: int = 1, keepdim: bool = False, sqrt: bool = False
) -> torch.Tensor:
    """``x.var(dim, correction=..., keepdim=...)`` (``x.std`` with ``sqrt``), thread-invariant.

    torch reduces a single output with its full-reduction variance (``std_var_all_cpu``):
    the mean in ``x``'s dtype, then ((x - mean)²).sum() accumulated in float64, one range per
    thread. With one thread that sum runs from the first element to the last, which
    ``cumsum`` (sequential on the CPU) replays. A two-row reduction would not do: torch takes
    Welford's algorithm there, whose bits differ even with one thread. (torch has no such
    full-reduction path for half precision, so those dtypes are its own call.)

    Args:
        x: the tensor.
        dim: the dimension to reduce.
        correction: subtracted from the count in the divisor (1: unbiased, 0: biased).
        keepdim: keep ``dim`` with size 1.
        sqrt: return the standard deviation.
    """
    if not _lone(x, dim) or x.dtype not in (torch.float32, torch.float64):
        reduce = x.std if sqrt else x.var
        return reduce(dim, correction=correction, keepdim=keepdim)
    flat = x.reshape(-1)
    deviations = flat.double() - mean_over(flat, 0).double()
    total = torch.cumsum(deviations * deviations, 0)[-1]
    var = total / max(0, flat.numel() - correction)
    out = (var.sqrt() if sqrt else var).to(x.dtype)
    shape = [1] * x.dim() if keepdim else [1] * (x.dim() - 1)
    return out.reshape(shape)


def std_over(x: torch.Tensor, dim: int, correction: int = 1, keepdim: bool = False) -> torch.Tensor:
    """``x.std(dim, correction=..., keepdim=...)``, thread-invariant (see :func:`var_over`)."""
    return var_over(x, dim, correction, keepdim, sqrt=True)
