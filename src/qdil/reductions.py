"""Sums, means and variances whose bits do not depend on torch's CPU thread count.

:func:`sum_over`, :func:`mean_over`, :func:`var_over` and :func:`std_over` give a reduction to
a single number over :data:`GRAIN_SIZE` or more CPU inputs the bits torch computes with one
thread; every other reduction is torch's own call. Why and how:
docs/concepts/reproducibility.md (section "torch's own reductions").
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
