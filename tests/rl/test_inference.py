"""Policy inference on the CPU: a row's bits do not depend on the batch, the threads or the CPU.

The kernel (:mod:`qdil.rl.inference`) is checked against a specification written here in
numpy, one float32 operation at a time over all rows at once (numpy's elementwise float32
arithmetic is IEEE's on every CPU): equal bit for bit, the row-independence follows. Its
``tanh`` is checked against the correctly rounded one.
"""

from __future__ import annotations

from functools import partial

import numba
import numpy as np
import pytest
import torch

from qdil.rl.inference import RowwisePolicies, tanh
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from qdil.rl.sampler import PolicySampler

F4 = np.float32


@numba.njit
def _tanh_all(x: np.ndarray) -> np.ndarray:  # pragma: no cover - numba
    out = np.empty_like(x)
    for i in range(x.shape[0]):
        out[i] = tanh(x[i])
    return out


def specification(actor, stats, clip, obs, noise):
    """The kernel's arithmetic, operation by operation, in numpy float32 (rows side by side)."""
    p_of = np.repeat(np.arange(actor.num_models), obs.shape[0] // actor.num_models)
    mean = stats.mean.to(torch.float32).numpy()[p_of]
    scale = torch.sqrt(stats.var + 1e-8).to(torch.float32).numpy()[p_of]
    norm = np.clip((obs - mean) / scale, F4(-clip), F4(clip))
    h = norm
    for i, (weight, bias) in enumerate(zip(actor.weights, actor.biases, strict=True)):
        w = weight.detach().numpy()[p_of]  # (n, out, in)
        y = np.zeros((len(h), w.shape[1]), F4)
        for k in range(w.shape[2]):  # in order, one product and one sum at a time
            y = y + h[:, k : k + 1] * w[:, :, k]
        y = y + bias.detach().numpy()[p_of]
        h = _tanh_all(y.ravel()).reshape(y.shape) if i < len(actor.weights) - 1 else y
    # per policy, computed once by torch (no row's arithmetic)
    std = actor.log_std.detach().exp()
    two_var, log_scale = (2 * std**2).numpy()[p_of], std.log().numpy()[p_of]
    std = std.numpy()[p_of]
    actions = h if noise is None else h + std * noise
    total = np.zeros(len(h), F4)
    for a in range(h.shape[1]):
        d = actions[:, a] - h[:, a]
        total = total + (-(d * d) / two_var[:, a] - log_scale[:, a] - F4(0.9189385332046727))
    return norm, actions, total


def policies(num: int, obs_dim: int, action_dim: int, hidden, seed: int = 0):
    rng = np.random.default_rng(seed)
    actor = VectorizedActor(num, obs_dim, action_dim, hidden)
    dim = VectorizedActor.solution_dim(obs_dim, action_dim, hidden)
    actor.set_solutions(rng.normal(0.0, 0.2, (num, dim)).astype(F4))
    stats = RunningMeanStd(num, (obs_dim,))
    stats.update(torch.as_tensor(rng.normal(0.5, 3.0, (num, 20, obs_dim))))
    return actor, stats


@pytest.mark.parametrize(
    ("num", "rows", "sizes"),
    [
        (3, 48, (17, (128, 128), 6)),  # Walker2d, laptop rollouts
        (64, 1, (17, (128, 128), 6)),  # branches scored with one episode each
        (2, 7, (348, (64, 33), 17)),  # Humanoid's sizes, widths no vector divides
    ],
)
@pytest.mark.parametrize("deterministic", [False, True])
def test_the_kernel_is_its_specification_bit_for_bit(num, rows, sizes, deterministic) -> None:
    obs_dim, hidden, action_dim = sizes
    actor, stats = policies(num, obs_dim, action_dim, hidden)
    rng = np.random.default_rng(1)
    obs = (rng.normal(0.0, 30.0, (num * rows, obs_dim))).astype(F4)
    noise = None if deterministic else rng.standard_normal((num * rows, action_dim)).astype(F4)
    sampler = PolicySampler(actor, stats, 10.0)
    got = sampler.sample(
        torch.from_numpy(obs),
        None,
        deterministic,
        noise=None if noise is None else torch.from_numpy(noise),
    )
    for mine, spec in zip(got, specification(actor, stats, 10.0, obs, noise), strict=True):
        np.testing.assert_array_equal(mine.numpy(), spec)


def test_tanh_is_correctly_rounded_but_for_near_ties() -> None:
    every = np.arange(0, np.float32(10).view(np.int32), 97, dtype=np.int32).view(F4)  # 11M
    x = np.concatenate([every, -every, F4([0.0, 1e-30, 5e-8, 0.015625, 9.1, 40.0, np.inf])])
    exact = np.tanh(x.astype(np.float64))
    got = _tanh_all(x)
    wrong = got != exact.astype(F4)
    assert wrong.mean() < 1e-6  # a near-tie rounds the other way: 4 of 365M floats in [0, 12]
    ulp = np.spacing(np.abs(exact).astype(F4)).astype(np.float64)
    assert (np.abs(got - exact) / ulp).max() < 0.5 + 1e-6
    assert np.array_equal(got.view(np.int32), (-_tanh_all(-x)).view(np.int32))  # odd, ±0 too
    assert np.isnan(_tanh_all(F4([np.nan]))).all()


@pytest.mark.parametrize("threads", [1, 2])
def test_a_row_gives_the_same_bits_alone_and_inside_3_8_33_and_512_rows(threads, at_threads):
    """Each batch holds the row at another place; one policy, then three side by side."""
    actor, stats = policies(3, 17, 6, (128, 128), seed=2)
    rng = np.random.default_rng(3)
    obs = torch.as_tensor(rng.normal(0.0, 5.0, (3 * 512, 17)), dtype=torch.float32)
    noise = torch.as_tensor(rng.standard_normal((3 * 512, 6)), dtype=torch.float32)
    row = 200  # of each policy's block of 512

    def sample(rows: slice, policies: list[int]):
        sub = VectorizedActor(len(policies), 17, 6)
        sub.set_solutions(actor.get_solutions()[policies])
        sampler = PolicySampler(sub, stats.select(policies), 10.0)
        blocks = [torch.arange(p * 512, (p + 1) * 512)[rows] for p in policies]
        pick = torch.cat(blocks)
        return sampler.sample(obs[pick], None, False, noise=noise[pick])

    before = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        alone = at_threads(threads, partial(sample, slice(row, row + 1), [0]))
        for size, place in ((3, 1), (8, 7), (33, 12), (512, row)):  # another place each time
            start = row - place
            for policies_ in ([0], [0, 1, 2]):
                got = at_threads(threads, partial(sample, slice(start, start + size), policies_))
                for one, many in zip(alone, got, strict=True):
                    assert torch.equal(one[0], many[place]), (size, policies_)
    finally:
        numba.set_num_threads(before)


def test_rowwise_policies_take_no_clip_as_none() -> None:
    actor, stats = policies(1, 17, 6, (8,))
    obs = torch.full((2, 17), 1e6)
    norm, _, _ = PolicySampler(actor, stats, None).sample(obs, None, True, log_probs=False)
    assert (norm.abs() > 1e4).all()
    assert isinstance(PolicySampler(actor, stats, None).rowwise, RowwisePolicies)


def test_observations_that_do_not_split_among_the_policies_are_refused() -> None:
    actor, stats = policies(3, 17, 6, (8,))
    with pytest.raises(ValueError, match="7 observations cannot be split among 3 policies"):
        PolicySampler(actor, stats, 10.0).sample(torch.zeros(7, 17), None, True)
