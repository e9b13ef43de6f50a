"""Cutting a batch of simulations into worker shards, and acting on one shard exactly as on all.

A shard is a contiguous range [start, stop) of the N simulation slots; policy p owns the
block [p·B, (p+1)·B). Two things make a shard's numbers those of the whole batch:

- the action noise: the head draws one (N, A) standard normal tensor per step from its
  generator; :class:`NoiseReplay` replays that stream from the generator's state and keeps
  the shard's rows (every worker draws N·A numbers per step: a few µs per thousand);
- the policies: :class:`ShardPolicies` runs each policy on its rows of the shard, and on
  the CPU a row's outputs do not depend on the rows computed beside it
  (:mod:`qdil.rl.inference`), so a shard may cut a policy's block anywhere.
"""

from __future__ import annotations

import itertools

import numpy as np
import torch

from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from qdil.rl.sampler import PolicySampler


def shard_bounds(n: int, num_shards: int) -> list[tuple[int, int]]:
    """Split n slots into at most ``num_shards`` contiguous, near-equal, non-empty shards.

    Args:
        n: slots N.
        num_shards: workers available.

    Returns:
        ``(start, stop)`` ranges covering [0, n) in order.
    """
    edges = sorted({round(i * n / num_shards) for i in range(num_shards + 1)})
    return list(itertools.pairwise(edges))


class NoiseReplay:
    """The head's per-step (N, A) action noise, restricted to rows [start, stop).

    Args:
        state: the head generator's state at the first step.
        rows: N.
        action_dim: A.
        start: first row of the shard.
        stop: end of the shard.
    """

    def __init__(
        self, state: torch.Tensor, rows: int, action_dim: int, start: int, stop: int
    ) -> None:
        self.generator = torch.Generator()
        self.generator.set_state(state)
        self.shape, self.start, self.stop = (rows, action_dim), start, stop

    def __call__(self) -> torch.Tensor:
        """(stop - start, A) noise of the next step."""
        return torch.randn(self.shape, generator=self.generator)[self.start : self.stop]


def advance(generator: torch.Generator, rows: int, action_dim: int, steps: int) -> None:
    """Draw what ``steps`` steps of local sampling draw, so the head's stream moves on alike."""
    for _ in range(steps):
        torch.randn((rows, action_dim), generator=generator)


class ShardPolicies:
    """P policies acting on the slots [start, stop) of a batch with blocks of ``block`` slots.

    Args:
        actor: all P policies.
        stats: their observation statistics.
        obs_clip: bound of normalised observations.
        start: first slot of the shard.
        stop: end of the shard.
        block: slots per policy B.
    """

    def __init__(
        self,
        actor: VectorizedActor,
        stats: RunningMeanStd,
        obs_clip: float,
        start: int,
        stop: int,
        block: int,
    ) -> None:
        policies = list(range(start // block, (stop - 1) // block + 1))
        pieces = [
            (max(start, p * block) - start, min(stop, (p + 1) * block) - start) for p in policies
        ]
        solutions = actor.get_solutions()
        obs_dim, hidden = actor.sizes[0], actor.sizes[1:-1]

        def sampler(index: list[int]) -> PolicySampler:
            part = VectorizedActor(len(index), obs_dim, actor.sizes[-1], hidden)
            part.set_solutions(solutions[index])
            return PolicySampler(part, stats.select(index), obs_clip)

        if len({b - a for a, b in pieces}) == 1:  # equal pieces: one call for all
            self.groups = [(0, stop - start, sampler(policies))]
        else:
            self.groups = [(a, b, sampler([p])) for p, (a, b) in zip(policies, pieces, strict=True)]

    def sample(
        self, obs: torch.Tensor, noise: torch.Tensor | None, deterministic: bool, log_probs: bool
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """``PolicySampler.sample`` on the shard's (n, obs_dim) observations and (n, A) noise."""
        outputs = [
            group.sample(
                obs[a:b], None, deterministic, log_probs, None if noise is None else noise[a:b]
            )
            for a, b, group in self.groups
        ]
        if len(outputs) == 1:
            return outputs[0]
        norm, actions, logp = zip(*outputs, strict=True)
        return (
            torch.cat(norm),
            torch.cat(actions),
            None if logp[0] is None else torch.cat(logp),  # type: ignore[arg-type]
        )


def payload_bytes(value: object) -> int:
    """Bytes of the tensors and arrays in ``value`` (what dominates its serialised size)."""
    if isinstance(value, torch.Tensor):
        return value.element_size() * value.numel()
    if isinstance(value, np.ndarray):
        return value.nbytes
    if isinstance(value, torch.nn.Module):
        return sum(payload_bytes(p) for p in value.state_dict().values())
    if isinstance(value, dict):
        return sum(payload_bytes(v) for v in value.values())
    if isinstance(value, list | tuple):
        return sum(payload_bytes(v) for v in value)
    if hasattr(value, "__dict__"):
        return payload_bytes(vars(value))
    return 0
