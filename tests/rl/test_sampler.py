"""The rollouts' policy sampler computes what the plain normalisation, forward and ``Normal`` do.

:class:`~qdil.rl.sampler.PolicySampler` precomputes what stays fixed during a rollout and
skips ``torch.distributions``. On a device it is the same arithmetic, compared with
``torch.equal`` (no tolerance); on the CPU each row is computed alone
(``tests/rl/test_inference.py`` checks its bits), which differs from torch's batched products
in the last bits only.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from qdil.rl.sampler import PolicySampler


def reference(actor, stats, obs, clip, generator, deterministic):
    """The computation before the sampler: normalize, forward, ``Normal``."""
    num = actor.num_models
    norm = stats.normalize(obs.reshape(num, -1, obs.shape[1]), clip=clip)
    with torch.no_grad():
        mean = actor(norm)
        std = actor.log_std.exp().unsqueeze(1).expand_as(mean)
        actions = (
            mean if deterministic else mean + std * torch.randn(mean.shape, generator=generator)
        )
        log_probs = torch.distributions.Normal(mean, std).log_prob(actions).sum(-1)
    return norm.reshape(obs.shape), actions.reshape(obs.shape[0], -1), log_probs.reshape(-1)


def compare(num_policies, num_obs, deterministic, device, equal) -> None:
    rng = np.random.default_rng(0)
    actor = VectorizedActor(num_policies, 17, 6)
    dim = VectorizedActor.solution_dim(17, 6)
    actor.set_solutions(rng.normal(0.0, 0.2, (num_policies, dim)).astype(np.float32))
    stats = RunningMeanStd(num_policies, (17,))
    stats.update(torch.as_tensor(rng.normal(0.5, 3.0, (num_policies, 20, 17))))
    actor, stats = actor.to(device), stats.to(device)
    sampler = PolicySampler(actor, stats, 10.0)
    mine = torch.Generator(device).manual_seed(1)
    theirs = torch.Generator(device).manual_seed(1)
    for _ in range(3):  # the sampler is reused step after step
        obs = torch.as_tensor(rng.normal(0.0, 30.0, (num_obs, 17)), dtype=torch.float32)
        got = sampler.sample(obs.to(device), mine, deterministic)
        expected = reference(actor, stats, obs.to(device), 10.0, theirs, deterministic)
        for a, b in zip(got, expected, strict=True):
            if equal:
                assert torch.equal(a, b)
            else:
                torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-5)
    _, _, none = sampler.sample(obs.to(device), mine, deterministic, log_probs=False)
    assert none is None


CASES = [(3, 48), (1, 5), (64, 64)]


@pytest.mark.parametrize("deterministic", [False, True])
@pytest.mark.parametrize(("num_policies", "num_obs"), CASES)
def test_sampler_on_the_cpu_equals_normal_to_the_last_bits(
    num_policies, num_obs, deterministic
) -> None:
    compare(num_policies, num_obs, deterministic, "cpu", equal=False)


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
@pytest.mark.parametrize("deterministic", [False, True])
@pytest.mark.parametrize(("num_policies", "num_obs"), CASES)
def test_sampler_on_a_device_equals_normal_bit_for_bit(
    num_policies, num_obs, deterministic
) -> None:
    compare(num_policies, num_obs, deterministic, "cuda", equal=True)
