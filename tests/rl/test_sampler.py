"""The rollouts' policy sampler equals the plain computation bit for bit, on any machine.

:class:`~qdil.rl.collect.PolicySampler` precomputes what stays fixed during a rollout and
skips ``torch.distributions``; here it is compared with the straightforward normalisation,
forward pass and ``Normal`` it replaces, with ``torch.equal`` (no tolerance).
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


@pytest.mark.parametrize("deterministic", [False, True])
@pytest.mark.parametrize(("num_policies", "num_obs"), [(3, 48), (1, 5), (64, 64)])
def test_sampler_equals_normal_bit_for_bit(num_policies, num_obs, deterministic) -> None:
    rng = np.random.default_rng(0)
    actor = VectorizedActor(num_policies, 17, 6)
    dim = VectorizedActor.solution_dim(17, 6)
    actor.set_solutions(rng.normal(0.0, 0.2, (num_policies, dim)).astype(np.float32))
    stats = RunningMeanStd(num_policies, (17,))
    stats.update(torch.as_tensor(rng.normal(0.5, 3.0, (num_policies, 20, 17))))
    sampler = PolicySampler(actor, stats, 10.0)
    mine, theirs = torch.Generator().manual_seed(1), torch.Generator().manual_seed(1)
    for _ in range(3):  # the sampler is reused step after step
        obs = torch.as_tensor(rng.normal(0.0, 30.0, (num_obs, 17)), dtype=torch.float32)
        got = sampler.sample(obs, mine, deterministic)
        expected = reference(actor, stats, obs, 10.0, theirs, deterministic)
        for a, b in zip(got, expected, strict=True):
            assert torch.equal(a, b)
    _, _, none = sampler.sample(obs, mine, deterministic, log_probs=False)
    assert none is None
