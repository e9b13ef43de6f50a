"""An environment's torch face: the host adapter of the C engine, or the device face.

:func:`torch_face` gives RL the :class:`~qdil.envs.torch_step.TorchFace` that fits where
``env.backend`` keeps its physics. The C engine's arrays are on the host and its episode
bookkeeping is gymnasium's numpy API (:class:`~qdil.envs.vector.LocomotionVectorEnv`,
bit-identical to gymnasium): :class:`HostFace` steps that API and hands its arrays on as CPU
tensors, without copying them. A device backend keeps its state in tensors on its device:
:class:`~qdil.envs.torch_vector.TorchVectorEnv` steps it there.
"""

from __future__ import annotations

import numpy as np
import torch
from gymnasium.vector import AutoresetMode

from qdil.devices import DEVICE_BACKENDS
from qdil.envs.torch_step import TorchFace, TorchStep
from qdil.envs.torch_vector import TorchVectorEnv
from qdil.envs.vector import LocomotionVectorEnv


def torch_face(env: LocomotionVectorEnv, reset_depth: int = 16) -> TorchFace:
    """The torch face that fits ``env.backend``.

    Args:
        env: an environment with ``autoreset_mode`` ``SAME_STEP`` (training) or ``DISABLED``
            (evaluation).
        reset_depth: initial states queued per sub-environment on a device
            (:class:`TorchVectorEnv`); the host face draws them when needed.
    """
    if env.backend in DEVICE_BACKENDS:
        return TorchVectorEnv(env, reset_depth)
    return HostFace(env)


class HostFace:
    """The torch face of an environment whose arrays are on the host (the C engine).

    Each step is one call of the environment's numpy ``step``; the step's arrays become CPU
    tensors that share their memory (every array ``step`` returns is new).

    Args:
        env: an environment with ``autoreset_mode`` ``SAME_STEP`` or ``DISABLED``.

    Raises:
        ValueError: for the ``NEXT_STEP`` autoreset mode.
    """

    side_by_side = False
    sync_every = 1

    def __init__(self, env: LocomotionVectorEnv) -> None:
        if env.autoreset_mode is AutoresetMode.NEXT_STEP:
            raise ValueError("a torch face supports autoreset_mode SAME_STEP and DISABLED")
        self.env = env
        self.num_envs, self.num_feet = env.num_envs, env.num_feet
        self.device = torch.device("cpu")  # the numpy arrays are on the host, whatever the backend
        self.action_low = env.single_action_space.low
        self.action_high = env.single_action_space.high
        self.autoreset = env.autoreset_mode is AutoresetMode.SAME_STEP
        n = env.num_envs
        # what a step without an episode end reports (never written to)
        self._no_return = torch.zeros(n, dtype=torch.float64)
        self._no_length = torch.zeros(n, dtype=torch.int64)
        self._no_measures = torch.zeros((n, env.num_feet), dtype=torch.float64)

    def reset(
        self, seed: int | list[int | None] | None = None, mask: np.ndarray | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The numpy face's ``reset``: (N, obs_dim) float64 observations, (N, k) contacts."""
        options = None if mask is None else {"reset_mask": np.asarray(mask, dtype=bool)}
        obs, info = self.env.reset(seed=seed, options=options)
        return torch.from_numpy(obs), torch.from_numpy(info["foot_contact"])

    def episode_statistics(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The numpy face's ``episode_statistics`` as tensors."""
        returns, lengths, measures = self.env.episode_statistics()
        return torch.from_numpy(returns), torch.from_numpy(lengths), torch.from_numpy(measures)

    def narrow(self, mask: torch.Tensor) -> None:
        """Nothing to do: the numpy face steps only the sub-environments a step's mask names."""

    def step(self, actions: torch.Tensor, mask: torch.Tensor | None = None) -> TorchStep:
        """The numpy face's ``step`` on (N, A) CPU actions, its arrays as tensors.

        Args:
            actions: (N, A) float32 CPU actions (checked by the environment: shape, NaN).
            mask: (N,) bool tensor of the sub-environments to advance (``DISABLED`` only).
        """
        action_array = actions.numpy()
        if not self.autoreset:
            # evaluation episodes hand the C engine float64 actions, training rollouts
            # float32 ones: the same values, but each control cost is computed in the
            # precision its pinned results were computed in
            action_array = action_array.astype(np.float64)
        obs, reward, terminated, truncated, info = self.env.step(
            action_array, mask=None if mask is None else mask.numpy()
        )
        contacts = info["foot_contact"]
        obs_t, contacts_t = torch.from_numpy(obs), torch.from_numpy(contacts)
        final_obs, final_contacts = obs_t, contacts_t  # the same tensors: nothing reset
        episode_return, episode_length = self._no_return, self._no_length
        episode_measures = self._no_measures
        if "episode" in info:
            episode = info["episode"]
            episode_return = torch.from_numpy(episode["r"])
            episode_length = torch.from_numpy(episode["l"])
            episode_measures = torch.from_numpy(episode["measures"])
            if self.autoreset:  # the step reached the final states, then reset them
                done = info["_final_obs"]
                reached, reached_contacts = obs.copy(), contacts.copy()
                reached[done] = info["final_obs"][done]
                reached_contacts[done] = info["final_info"]["foot_contact"][done]
                final_obs = torch.from_numpy(reached)
                final_contacts = torch.from_numpy(reached_contacts)
        return TorchStep(
            obs=obs_t,
            final_obs=final_obs,
            reward=torch.from_numpy(reward),
            terminated=torch.from_numpy(terminated),
            done=torch.from_numpy(terminated | truncated),
            contacts=contacts_t,
            final_contacts=final_contacts,
            episode_return=episode_return,
            episode_length=episode_length,
            episode_measures=episode_measures,
        )
