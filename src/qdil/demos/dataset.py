"""``DemoSet``: a few expert episodes as aligned arrays (s_t, a_t, δ(s_t), r_t)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from qdil.data import TransitionBatch


@dataclass(frozen=True)
class DemoSet:
    """Expert demonstrations, episodes concatenated along time.

    Attributes:
        task: gymnasium task id, e.g. ``"Walker2d-v5"``.
        obs: (T, obs_dim) raw observations s_t.
        actions: (T, action_dim) executed actions a_t.
        contacts: (T, k) foot-contact flags δ(s_t).
        rewards: (T,) true rewards r_t.
        next_obs: (T, obs_dim) raw s_{t+1} (the final observation at an episode end).
        next_contacts: (T, k) flags δ(s_{t+1}).
        episode_ends: (E,) index one past each episode's last step; the last equals T.
        terminated: (E,) whether each episode ended by termination (not the time limit).
        metadata: provenance (run, recipe, seed, code version, elites, ...).
    """

    task: str
    obs: np.ndarray
    actions: np.ndarray
    contacts: np.ndarray
    rewards: np.ndarray
    next_obs: np.ndarray
    next_contacts: np.ndarray
    episode_ends: np.ndarray
    terminated: np.ndarray
    metadata: dict = field(default_factory=dict)

    @property
    def num_episodes(self) -> int:
        """E."""
        return len(self.episode_ends)

    @property
    def episode_starts(self) -> np.ndarray:
        """(E,) index of each episode's first step."""
        return np.r_[0, self.episode_ends[:-1]]

    @property
    def lengths(self) -> np.ndarray:
        """(E,) episode lengths."""
        return self.episode_ends - self.episode_starts

    @property
    def returns(self) -> np.ndarray:
        """(E,) true returns."""
        return (
            np.add.reduceat(self.rewards, self.episode_starts) if len(self.rewards) else np.zeros(0)
        )

    @property
    def measures(self) -> np.ndarray:
        """(E, k) episode measures: mean of the post-step flags δ(s_{t+1})."""
        sums = np.add.reduceat(self.next_contacts, self.episode_starts, axis=0)
        return sums / self.lengths[:, None]

    def terminated_steps(self) -> np.ndarray:
        """(T,) 1.0 at the last step of each episode that ended by termination."""
        out = np.zeros(len(self.obs), dtype=np.float32)
        out[self.episode_ends[np.asarray(self.terminated, dtype=bool)] - 1] = 1.0
        return out

    def dones(self) -> np.ndarray:
        """(T,) 1.0 at each episode's last step."""
        out = np.zeros(len(self.obs), dtype=np.float32)
        out[self.episode_ends - 1] = 1.0
        return out

    def transitions(self) -> TransitionBatch:
        """All steps as a flat batch (log-probabilities unknown: NaN)."""

        def tensor(x: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(np.asarray(x, dtype=np.float32))

        return TransitionBatch(
            obs=tensor(self.obs),
            actions=tensor(self.actions),
            contacts=tensor(self.contacts),
            next_obs=tensor(self.next_obs),
            next_contacts=tensor(self.next_contacts),
            dones=tensor(self.dones()),
            log_probs=torch.full((len(self.obs),), float("nan")),
            terminated=tensor(self.terminated_steps()),
        )
