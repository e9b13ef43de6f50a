"""The one step interface of RL: a vector environment that takes and returns torch tensors.

Rollouts (:mod:`qdil.rl.collect`) and evaluation episodes (:mod:`qdil.rl.episodes`) step
every backend through a :class:`TorchFace`: actions go in as an (N, A) tensor on the face's
device, and one :class:`TorchStep` of (N, ...) tensors comes out. Two faces implement it
(:func:`qdil.envs.faces.torch_face` picks the one that fits ``env.backend``): the C engine's
:class:`~qdil.envs.faces.HostFace`, a thin adapter over gymnasium's numpy API, and the
device face :class:`~qdil.envs.torch_vector.TorchVectorEnv`, which keeps everything on the
physics' device.
"""

from __future__ import annotations

from typing import NamedTuple, Protocol

import numpy as np
import torch


class TorchStep(NamedTuple):
    """One env step of N sub-environments, (N, ...) tensors on the face's device.

    A named tuple: built once per step, where a frozen dataclass's construction alone
    costs microseconds.

    Attributes:
        obs: float64 observations to act on next (after an autoreset, the new episode's).
        final_obs: float64 observations of the states the step reached (before a reset).
        reward: float64 true rewards (0 for sub-environments left out of the step).
        terminated: bool, the episode ended because the robot is unhealthy.
        done: bool, the episode ended: terminated, or truncated at ``max_episode_steps``.
        contacts: float32 0/1 foot-contact flags of ``obs``'s states.
        final_contacts: float32 foot-contact flags of ``final_obs``'s states.
        episode_return: float64 true return of the episodes that ended (0 elsewhere).
        episode_length: int64 lengths of the episodes that ended (0 elsewhere).
        episode_measures: (N, k) float64 mean foot contacts of the episodes that ended.
    """

    obs: torch.Tensor
    final_obs: torch.Tensor
    reward: torch.Tensor
    terminated: torch.Tensor
    done: torch.Tensor
    contacts: torch.Tensor
    final_contacts: torch.Tensor
    episode_return: torch.Tensor
    episode_length: torch.Tensor
    episode_measures: torch.Tensor


class TorchFace(Protocol):
    """A vector environment stepped from and into torch tensors on :attr:`device`.

    Attributes:
        num_envs: sub-environments N.
        num_feet: measures k.
        device: where the step's tensors are (the physics' device; the host's for the C
            engine's numpy arrays).
        action_low: (A,) lower action bounds.
        action_high: (A,) upper action bounds.
        autoreset: whether a finished sub-environment resets within its step
            (``SAME_STEP``, training) or waits to be reset (``DISABLED``, evaluation).
        side_by_side: whether evaluations play several groups of policies side by side in
            one batch (a device, where a step costs the same however many simulations it
            advances) or one after the other (the C engine, whose cost follows them).
        sync_every: steps between two looks from the host at whether an evaluation's
            episodes still run (1 where the arrays are on the host and a look is free).
    """

    num_envs: int
    num_feet: int
    device: torch.device
    action_low: np.ndarray
    action_high: np.ndarray
    autoreset: bool
    side_by_side: bool
    sync_every: int

    def reset(
        self, seed: int | list[int | None] | None = None, mask: np.ndarray | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Reset every sub-environment, or those in the (N,) bool ``mask``.

        Args:
            seed: reset seed (gymnasium's rule: sub-environment i gets ``seed + i``), one
                seed per sub-environment, or ``None`` to go on with the generators' streams.
            mask: (N,) bool numpy array of the sub-environments to reset; ``None`` for all.

        Returns:
            (N, obs_dim) float64 observations and (N, k) float32 foot contacts.
        """
        ...

    def episode_statistics(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Return (N,) float64, length (N,) int64, measures (N, k) float64 of each episode.

        Each sub-environment's current or last episode: with autoreset disabled a finished
        sub-environment keeps them until it is reset (what the step that ended it reported).
        """
        ...

    def narrow(self, mask: torch.Tensor) -> None:
        """Simulate only the sub-environments in ``mask`` until the next reset (a hint).

        Where the physics steps every simulation of a batch (MuJoCo Warp), the ones in the
        (N,) bool ``mask`` move to a smaller batch and the others stop costing physics;
        results do not change. Steps must then leave the others out of their ``mask``.
        """
        ...

    def step(self, actions: torch.Tensor, mask: torch.Tensor | None = None) -> TorchStep:
        """Advance the sub-environments by one env step.

        Args:
            actions: (N, A) float32 executed actions on :attr:`device`.
            mask: (N,) bool tensor of the sub-environments to advance (autoreset disabled
                only); the others keep their state and report reward 0 and no episode end.

        Returns:
            The step's tensors.
        """
        ...
