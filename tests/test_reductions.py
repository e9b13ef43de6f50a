"""qdil.reductions: a single output takes torch's one-thread bits with any thread count."""

from __future__ import annotations

from functools import partial

import pytest
import torch

from qdil.reductions import GRAIN_SIZE, mean_over, std_over, sum_over, var_over


def sample(shape: tuple[int, ...], dtype: torch.dtype, seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    return torch.randn(shape, generator=g, dtype=dtype) * 3 + torch.rand((), generator=g) * 5


# qdil's single-output reductions at paper scale (3000 simulations x 128 steps, 8 minibatches)
# and, last, the test-scale walk critic's 256 x 256 layer in the gradient clipping
LONE = [
    ("sum", lambda x: x.sum(1), lambda x: sum_over(x, 1), (1, 65536), torch.float32),
    (
        "bias gradient",
        lambda x: x.sum(1, keepdim=True),
        lambda x: sum_over(x, 1, keepdim=True),
        (1, 48000, 1),
        torch.float32,
    ),
    ("minibatch mean", lambda x: x.mean(1), lambda x: mean_over(x, 1), (1, 48000), torch.float32),
    (
        "advantage std",
        lambda x: x.std(1, keepdim=True),
        lambda x: std_over(x, 1, keepdim=True),
        (1, 48000),
        torch.float32,
    ),
    ("return mean", lambda x: x.mean(1), lambda x: mean_over(x, 1), (1, 384000), torch.float64),
    (
        "return variance",
        lambda x: x.var(1, unbiased=False),
        lambda x: var_over(x, 1, correction=0),
        (1, 384000),
        torch.float64,
    ),
    (
        "explained variance",
        lambda x: x.reshape(-1).var(),
        lambda x: var_over(x.reshape(-1), 0),
        (3, 128000),
        torch.float32,
    ),
]


@pytest.mark.parametrize(
    ("name", "torch_op", "ours", "shape", "dtype"), LONE, ids=[case[0] for case in LONE]
)
def test_a_single_output_has_the_one_thread_bits_with_two_threads(
    name, torch_op, ours, shape, dtype, at_threads
) -> None:
    for seed in range(8):
        x = sample(shape, dtype, seed)
        one = at_threads(1, partial(torch_op, x))
        for threads in (1, 2):
            got = at_threads(threads, partial(ours, x))
            assert got.shape == one.shape and torch.equal(got, one), (name, seed, threads)


@pytest.mark.parametrize(
    "shape",
    [(3, 65536), (1, GRAIN_SIZE - 1), (1, 96, 1), (2, 48000, 6), (1, 3000, 17)],
)
def test_other_reductions_are_torchs_own(shape) -> None:
    x = sample(shape, torch.float64, 0)
    assert torch.equal(sum_over(x, 1), x.sum(1))
    assert torch.equal(mean_over(x, 1, keepdim=True), x.mean(1, keepdim=True))
    assert torch.equal(var_over(x, 1, correction=0), x.var(1, unbiased=False))
    assert torch.equal(std_over(x, 1), x.std(1))


def test_the_two_row_view_carries_the_gradient_of_a_sum() -> None:
    x = sample((1, 40000), torch.float32, 0).requires_grad_()
    (sum_over(x, 1) * 3.0).sum().backward()
    assert x.grad is not None and torch.equal(x.grad, torch.full_like(x, 3.0))
