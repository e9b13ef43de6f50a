"""The exchange formats of qdil: rollouts, transition batches and demonstrations.

Every array here holds *raw* (unnormalised) observations and the actions the environment
executed; whoever needs normalised inputs (the policy, a reward model) normalises them
itself, so expert and policy data are always treated the same way (decision D4).

Shapes use T for time steps, N for parallel environments, B for a flat batch, and
``obs_dim``, ``action_dim`` and k (number of measures) for the task's sizes.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import torch


@dataclass(frozen=True)
class TransitionBatch:
    """A flat batch of transitions (s_t, a_t, δ(s_t), s_{t+1}).

    Attributes:
        obs: (B, obs_dim) raw observations s_t.
        actions: (B, action_dim) executed actions a_t.
        contacts: (B, k) foot-contact flags δ(s_t) of s_t.
        next_obs: (B, obs_dim) raw observations s_{t+1} (the final one at an episode end).
        next_contacts: (B, k) flags δ(s_{t+1}).
        dones: (B,) 1.0 where the episode ended at this step (terminated or truncated).
        log_probs: (B,) log π(a_t | s_t) of the acting policy, or NaN where unknown (demos).
        terminated: (B,) 1.0 where the episode ended by termination (not the time limit);
            zeros when not given.
        absorbing: (B,) 1.0 for a transition of the absorbing state that follows a
            termination (:meth:`with_absorbing`); its other fields are zeros. Zeros when
            not given.
    """

    obs: torch.Tensor
    actions: torch.Tensor
    contacts: torch.Tensor
    next_obs: torch.Tensor
    next_contacts: torch.Tensor
    dones: torch.Tensor
    log_probs: torch.Tensor
    terminated: Any = None
    absorbing: Any = None

    def __post_init__(self) -> None:
        for name in ("terminated", "absorbing"):
            if getattr(self, name) is None:  # frozen: set once, here
                object.__setattr__(self, name, torch.zeros_like(self.dones))

    def __len__(self) -> int:
        return self.obs.shape[0]

    def __getitem__(self, index: torch.Tensor | slice) -> TransitionBatch:
        """The sub-batch at ``index`` (indices, mask or slice over B)."""
        return TransitionBatch(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    def to(self, device: torch.device | str) -> TransitionBatch:
        """The batch on ``device``."""
        return TransitionBatch(**{f.name: getattr(self, f.name).to(device) for f in fields(self)})

    def sample(self, size: int, generator: torch.Generator | None = None) -> TransitionBatch:
        """``size`` transitions drawn uniformly with replacement."""
        index = torch.randint(len(self), (size,), generator=generator)
        return self[index]

    @staticmethod
    def cat(batches: list[TransitionBatch]) -> TransitionBatch:
        """Concatenate batches along B."""
        return TransitionBatch(
            **{f.name: torch.cat([getattr(b, f.name) for b in batches]) for f in fields(batches[0])}
        )

    def with_absorbing(self) -> TransitionBatch:
        """The batch followed by one absorbing transition per terminated transition.

        As in DAC (Kostrikov et al., ICLR 2019), an episode that terminates enters an
        absorbing state it never leaves, so a reward model can learn what that state is
        worth instead of the implicit zero of a return that stops. Here the absorbing state
        is entered from a particular terminal transition and keeps its inputs: each added
        transition is a copy of a terminated one with ``absorbing`` = 1 (and ``dones`` and
        ``terminated`` 0). The batch itself when nothing terminated.
        """
        ended = self.terminated > 0
        if not bool(ended.any()):
            return self
        copies = self[ended]
        count = len(copies)
        absorbing = TransitionBatch(
            **{f.name: getattr(copies, f.name) for f in fields(self)}
            | {
                "dones": copies.dones.new_zeros(count),
                "terminated": copies.terminated.new_zeros(count),
                "absorbing": copies.absorbing.new_ones(count),
            }
        )
        return TransitionBatch.cat([self, absorbing])

    def absorbing_copies(self) -> TransitionBatch:
        """Every transition marked as the absorbing state entered from it."""
        return TransitionBatch(
            **{f.name: getattr(self, f.name) for f in fields(self)}
            | {"absorbing": torch.ones_like(self.dones)}
        )


@dataclass(frozen=True)
class Rollout:
    """Time-major transitions of N environments over T steps.

    Reward models score a rollout in this layout (``predict_reward``) because some rewards
    depend on the episode so far (PWIL) or on counts that evolve step by step (the
    exploration bonus).

    Attributes:
        obs: (T, N, obs_dim) raw observations s_t.
        actions: (T, N, action_dim) executed actions a_t.
        contacts: (T, N, k) flags δ(s_t).
        next_obs: (T, N, obs_dim) raw s_{t+1} (the final observation at an episode end).
        next_contacts: (T, N, k) flags δ(s_{t+1}) after the step.
        rewards: (T, N) the task's true rewards r_t.
        dones: (T, N) 1.0 where the episode ended at step t.
        terminated: (T, N) 1.0 where it ended by termination (not by the time limit).
        log_probs: (T, N) log π(a_t | s_t) of the acting policy.
        valid: (T, N) 1.0 for real transitions; 0.0 pads evaluation rollouts after an
            environment's episode ended.
        starts: (T, N) 1.0 where s_t is the first observation of an episode. Consecutive
            training rollouts of one phase continue each other column by column, and every
            phase begins with a reset, so stateful rewards (PWIL) can follow episodes.
    """

    obs: torch.Tensor
    actions: torch.Tensor
    contacts: torch.Tensor
    next_obs: torch.Tensor
    next_contacts: torch.Tensor
    rewards: torch.Tensor
    dones: torch.Tensor
    terminated: torch.Tensor
    log_probs: torch.Tensor
    valid: torch.Tensor
    starts: torch.Tensor

    @property
    def num_steps(self) -> int:
        """T."""
        return self.obs.shape[0]

    @property
    def num_envs(self) -> int:
        """N."""
        return self.obs.shape[1]

    def flat(self) -> TransitionBatch:
        """All T·N transitions as a flat batch in time-major order (padding included)."""
        names = (
            "obs", "actions", "contacts", "next_obs", "next_contacts", "dones", "log_probs",
            "terminated",
        )  # fmt: skip
        return TransitionBatch(
            **{
                name: getattr(self, name).reshape(-1, *getattr(self, name).shape[2:])
                for name in names
            }
        )

    def transitions(self) -> TransitionBatch:
        """The valid transitions as a flat batch (time-major order)."""
        return self.flat()[self.valid.reshape(-1) > 0]

    def columns(self, start: int, stop: int) -> Rollout:
        """Environments ``start:stop`` of the rollout (along N)."""
        return Rollout(**{f.name: getattr(self, f.name)[:, start:stop] for f in fields(self)})
