"""``TorchVectorEnv``: the torch face of a vector environment whose physics is on a device.

On a device backend (``env.backend: warp``) RL steps this face
(:class:`~qdil.envs.torch_step.TorchFace`): the task formulas run on torch tensors on the
physics' device (:mod:`qdil.envs.arrays`), with no host copy and no host sync per step.
Two things need the host and stay off the per-step path: the reset noise, drawn by each
sub-environment's numpy generator (gymnasium's seeding) ``reset_depth`` initial states
ahead into queues on the device, and knowing whether any world finished, which the
autoreset avoids by resetting the finished worlds in place (``WarpBatch.reset_where``).
Rollouts through it equal those through the host face of the same environment
(``tests/rl/test_collect_device.py``; ``docs/concepts/vppo.md``).
"""

from __future__ import annotations

import numpy as np
import torch
from gymnasium.vector import AutoresetMode

from qdil.devices import DEVICE_BACKENDS
from qdil.envs.step_graph import StepGraph
from qdil.envs.torch_step import TorchStep
from qdil.envs.vector import LocomotionVectorEnv


class TorchVectorEnv:
    """Steps a :class:`LocomotionVectorEnv` from and into torch tensors on its device.

    The wrapped environment's numpy face must not be stepped meanwhile: the two faces keep
    their own episode statistics.

    Args:
        env: an environment on a device backend, ``autoreset_mode`` ``SAME_STEP`` (training)
            or ``DISABLED`` (evaluation).
        reset_depth: initial states queued per sub-environment (``SAME_STEP``); the queues
            are topped up from the host every ``reset_depth`` steps.

    Raises:
        ValueError: for a backend whose arrays are on the host, naming ``env.backend``, or
            the ``NEXT_STEP`` autoreset mode.
    """

    side_by_side = True
    sync_every = 16
    step_graph = False
    """Record a training step (autoreset on, CUDA) in one CUDA graph and replay it
    (:class:`~qdil.envs.step_graph.StepGraph`); off until a GPU check has measured it."""

    def __init__(self, env: LocomotionVectorEnv, reset_depth: int = 16) -> None:
        if env.backend not in DEVICE_BACKENDS:
            raise ValueError(
                f"env.backend: {env.backend} hands numpy arrays to the host; the device face "
                "needs a device backend (env.backend: warp)"
            )
        if env.autoreset_mode is AutoresetMode.NEXT_STEP:
            raise ValueError("a torch face supports autoreset_mode SAME_STEP and DISABLED")
        if reset_depth < 1:
            raise ValueError(f"reset_depth must be at least 1, got {reset_depth}")
        self.env, self.task, self.physics = env, env.task, env.physics
        self.device = env.device
        self.action_low = env.single_action_space.low
        self.action_high = env.single_action_space.high
        self.num_envs = n = env.num_envs
        self.num_feet = k = env.num_feet
        self.autoreset = env.autoreset_mode is AutoresetMode.SAME_STEP
        self.reset_depth = reset_depth
        self._slices = env.physics.slices
        on = {"device": self.device}
        self._position = self.task.position(self._arrays())
        self._elapsed = torch.zeros(n, dtype=torch.int64, **on)
        self._return = torch.zeros(n, dtype=torch.float64, **on)
        self._contact_sum = torch.zeros((n, k), dtype=torch.float64, **on)
        self._obs = self.task.observation(self._arrays())
        self._rows = torch.arange(n, **on)
        model = env.model
        self._queue_qpos = torch.zeros((n, reset_depth, model.nq), dtype=torch.float64, **on)
        self._queue_qvel = torch.zeros((n, reset_depth, model.nv), dtype=torch.float64, **on)
        self._used = torch.zeros(n, dtype=torch.int64, **on)  # states taken, per sim
        self._drawn = np.zeros(n, dtype=np.int64)  # states queued so far, per sim
        self._since_top_up = 0
        self._graph: StepGraph | None = None

    # ----------------------------------------------------------------- helpers
    def _arrays(self) -> dict[str, torch.Tensor]:
        """The exported arrays as float64 device tensors (the numpy face's float64 values)."""
        exported = self.physics.torch_exported.double()
        return {name: exported[:, cols] for name, cols in self._slices.items()}

    def _contacts(self) -> torch.Tensor:
        return (self.physics.torch_sensordata > 0).to(torch.float32)

    def _top_up(self) -> None:
        """Queue new initial states for the ones taken since the last top-up (one sync)."""
        used = self._used.cpu().numpy()
        missing = used + self.reset_depth - self._drawn
        ids = np.repeat(np.arange(self.num_envs), missing)
        if ids.size:
            # state number drawn, drawn + 1, ... of each sim, in its generator's order
            first = np.repeat(np.cumsum(missing) - missing, missing)
            slots = np.repeat(self._drawn, missing) + np.arange(ids.size) - first
            qpos, qvel = self.env.draw_initial_states(ids)
            rows, slots_t = self._upload(ids), self._upload(slots % self.reset_depth)
            self._queue_qpos[rows, slots_t] = self._upload(qpos)
            self._queue_qvel[rows, slots_t] = self._upload(qvel)
        self._drawn = used + self.reset_depth
        self._since_top_up = 0

    def _upload(self, array: np.ndarray) -> torch.Tensor:
        """``array`` as a tensor on the device, sent without waiting for the device.

        A copy from pageable host memory makes torch wait for the stream; one from pinned
        memory does not (torch's pinned allocator keeps the buffer until the copy is done).
        On an H200 the four pageable copies of a top-up were four of its five syncs.
        """
        tensor = torch.from_numpy(array)
        if self.device.type != "cuda":
            return tensor.to(self.device)
        return tensor.pin_memory().to(self.device, non_blocking=True)

    def episode_statistics(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(N,) return, (N,) length and (N, k) measures of each current or last episode.

        With autoreset disabled a finished sub-environment keeps them until it is reset:
        they are what the step that ended its episode reported.
        """
        length = self._elapsed.clamp(min=1)
        return self._return.clone(), self._elapsed.clone(), self._contact_sum / length[:, None]

    def _start_episodes(self, mask: torch.Tensor) -> None:
        """Zero the episode statistics where ``mask`` (N,) holds, after a physics reset."""
        position = self.task.position(self._arrays())
        wide = mask if position.dim() == 1 else mask[:, None]
        self._position.copy_(torch.where(wide, position, self._position))
        self._elapsed.masked_fill_(mask, 0)
        self._return.masked_fill_(mask, 0.0)
        self._contact_sum.masked_fill_(mask[:, None], 0.0)

    # --------------------------------------------------------------------- API
    def reset(
        self, seed: int | list[int | None] | None = None, mask: np.ndarray | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Reset every sub-environment, or those in ``mask``, as the numpy face's ``reset``.

        Args:
            seed: reset seed (gymnasium's rule: sub-environment i gets ``seed + i``).
            mask: (N,) bool numpy array of the sub-environments to reset; ``None`` for all.

        Returns:
            (N, obs_dim) float64 observations and (N, k) float32 foot contacts.
        """
        self.env.seed_generators(seed)
        mask = np.ones(self.num_envs, dtype=bool) if mask is None else np.asarray(mask, bool)
        ids = np.flatnonzero(mask)
        qpos, qvel = self.env.draw_initial_states(ids)
        self.physics.reset(ids, qpos, qvel)
        mask_t = torch.from_numpy(mask).to(self.device)
        self._start_episodes(mask_t)
        observed = self.task.observation(self._arrays())
        self._obs.copy_(torch.where(mask_t[:, None], observed, self._obs))
        if self.autoreset:
            self._used.zero_()
            self._drawn[:] = 0
            self._top_up()
        return self._obs.clone(), self._contacts()

    def narrow(self, mask: torch.Tensor) -> None:
        """Simulate only the sub-environments in the (N,) bool ``mask`` until the next reset.

        The physics moves them to a smaller batch (:meth:`WarpBatch.narrow`); a reset moves
        them back. One host sync (the number of simulations kept sets the batch's size).
        """
        self.physics.narrow(torch.nonzero(mask).flatten())

    def step(self, actions: torch.Tensor, mask: torch.Tensor | None = None) -> TorchStep:
        """Advance the sub-environments by one env step, on the device.

        Args:
            actions: (N, action_dim) float32 actions on the device (unchecked: a check for
                NaN would cost a sync).
            mask: (N,) bool tensor of the sub-environments to advance (``DISABLED`` only);
                the others keep their state and report reward 0 and no episode end. Leave
                finished episodes out: unlike the numpy face, nothing stops them (a check
                would cost a sync).

        Returns:
            The step's tensors.
        """
        if mask is not None and self.autoreset:
            raise ValueError("step(mask=...) needs autoreset_mode=DISABLED")
        if self.autoreset and self._since_top_up == self.reset_depth:
            self._top_up()
        self._since_top_up += 1
        if not (self.step_graph and self.autoreset and self.device.type == "cuda"):
            return self._advance(actions, mask)
        if self._graph is None:
            self._graph = StepGraph(self._advance, actions, self.physics.graphs)
        world_steps = self.physics.world_steps
        result = self._graph(actions)
        self.physics.world_steps = world_steps + self.num_envs  # a replay runs no Python
        return result

    def _advance(self, actions: torch.Tensor, mask: torch.Tensor | None = None) -> TorchStep:
        """:meth:`step` after the top-up: on the device only, the state updated in place."""
        stepping = torch.ones(self.num_envs, dtype=torch.bool, device=self.device)
        if mask is not None:
            stepping = mask
        task = self.task
        self.physics.step_torch(actions, task.frame_skip, mask)
        x = self._arrays()

        position = task.position(x)
        velocity = (position - self._position) / task.dt
        wide = stepping if position.dim() == 1 else stepping[:, None]
        self._position.copy_(torch.where(wide, position, self._position))
        reward, _ = task.reward(velocity, actions, x)
        reward = torch.where(stepping, reward.to(torch.float64), 0.0)
        terminated = task.terminated(x) & stepping
        self._elapsed.add_(stepping)
        truncated = torch.zeros_like(terminated)
        if self.env.max_episode_steps is not None:
            truncated = (self._elapsed >= self.env.max_episode_steps) & stepping
        contacts = self._contacts()
        obs = task.observation(x)
        self._return.add_(reward)
        self._contact_sum.add_(torch.where(stepping[:, None], contacts, 0.0))
        done = terminated | truncated
        length = self._elapsed.clamp(min=1)
        episode_return = torch.where(done, self._return, 0.0)
        episode_length = torch.where(done, self._elapsed, 0)
        measures = torch.where(done[:, None], self._contact_sum / length[:, None], 0.0)
        final_obs, final_contacts = obs, contacts
        if self.autoreset:  # the finished worlds take their next queued initial state
            slot = self._used % self.reset_depth
            self.physics.reset_where(
                done, self._queue_qpos[self._rows, slot], self._queue_qvel[self._rows, slot]
            )
            self._used.add_(done)
            self._start_episodes(done)
            obs = torch.where(done[:, None], task.observation(self._arrays()), obs)
            contacts = torch.where(done[:, None], self._contacts(), contacts)
        self._obs.copy_(obs)
        return TorchStep(
            obs=obs,
            final_obs=final_obs,
            reward=reward,
            terminated=terminated,
            done=done,
            contacts=contacts,
            final_contacts=final_contacts,
            episode_return=episode_return,
            episode_length=episode_length,
            episode_measures=measures,
        )
