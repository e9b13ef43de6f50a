"""``LocomotionVectorEnv``: N copies of a task as one gymnasium ``VectorEnv``.

All simulations advance in one call (:class:`~qdil.envs.physics.MujocoBatch`), and
observations, rewards and terminations are computed for the whole batch with numpy. The
environment follows gymnasium's vector API, including its autoreset modes, and reproduces
``gymnasium.make_vec(task, vectorization_mode="sync")`` step for step: each sub-environment
draws its reset noise from its own generator, seeded as gymnasium seeds sub-environment i
(``seed + i``).

Beyond gymnasium's keys, every ``info`` carries ``foot_contact`` and ``episode``:
- ``foot_contact``: (N, k) float32 0/1 flags, foot j touching the floor in the state the
  info describes (after the step, or after the reset).
- ``episode``: at the step where an episode ends, a dict with the episode's true return
  ``r`` (N,), length ``l`` (N,) and measures ``measures`` (N, k), the mean of the step flags
  over the episode; ``_episode`` masks the environments whose episode ended.
"""

from __future__ import annotations

from functools import partial
from typing import Any

import gymnasium
import mujoco
import numpy as np
import torch
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from qdil.devices import run_device
from qdil.envs.backends import make_physics
from qdil.envs.rendering import CAMERA_DISTANCE, RENDER_MODES, StateRenderer
from qdil.envs.tasks import LocomotionTask, make_task


class LocomotionVectorEnv(VectorEnv):
    """A batch of one MuJoCo locomotion task with per-step foot-contact measures.

    Args:
        task: a task id such as ``"Walker2d-v5"`` or a :class:`LocomotionTask`.
        num_envs: number of sub-environments N.
        max_episode_steps: truncation horizon (gymnasium's ``TimeLimit``); ``None`` for none.
        autoreset_mode: gymnasium's ``AutoresetMode`` (or its string value).
            ``NEXT_STEP`` (gymnasium's default): the step after an episode ends resets that
            sub-environment and ignores its action. ``SAME_STEP``: finished
            sub-environments reset within the step; their last observation and info are in
            ``info["final_obs"]`` (a dense (N, obs_dim) array masked by ``_final_obs``) and
            ``info["final_info"]``. ``DISABLED``: call ``reset(options={"reset_mask": m})``.
        num_threads: physics threads; ``None`` uses every available core.
        backend: physics engine, ``"mujoco"`` (MuJoCo's C engine, :class:`MujocoBatch`) or
            ``"warp"`` (MuJoCo Warp, :class:`~qdil.envs.warp_physics.WarpBatch`).
        device: where the physics runs, ``"cpu"`` or ``"cuda[:N]"`` (``warp`` only);
            checked here with ``backend`` (:func:`qdil.devices.run_device`), before
            anything is built.
        deterministic: ``warp``: MuJoCo Warp's deterministic kernels (``env.deterministic``).
        integrator: one in place of the model file's (``env.integrator``,
            :mod:`qdil.envs.integrators`); ``None`` keeps it: the gymnasium task.
        render_mode: ``"rgb_array"``: :meth:`render` draws the first simulation
            (:mod:`qdil.envs.rendering`); ``None``: no rendering.
        **task_kwargs: gymnasium's keyword arguments of the task, e.g. ``ctrl_cost_weight``.

    Attributes:
        device: the ``torch.device`` of the physics, which everything stepping it uses.
        factory: a picklable maker of the same task, horizon and backend, called as
            ``factory(num_envs, autoreset_mode=..., num_threads=...)``.

    Raises:
        ValueError: for an unknown task, keyword, autoreset or render mode, a bad size, or
            a backend and device that do not go together (naming ``env.backend`` or
            ``env.device``).
    """

    def __init__(
        self,
        task: str | LocomotionTask = "Walker2d-v5",
        num_envs: int = 1,
        max_episode_steps: int | None = 1000,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        num_threads: int | None = None,
        backend: str = "mujoco",
        device: str | torch.device = "cpu",
        render_mode: str | None = None,
        deterministic: bool = False,
        integrator: str | None = None,
        **task_kwargs: Any,
    ) -> None:
        self.backend, self.device = backend, run_device(backend, device)
        # how to build this task again elsewhere (a remote worker's shard): by name, so that
        # a worker finds the model files of its own installation
        self.factory = partial(
            LocomotionVectorEnv,
            task,
            max_episode_steps=max_episode_steps,
            backend=backend,
            device=self.device,
            deterministic=deterministic,
            integrator=integrator,
            **task_kwargs,
        )
        if isinstance(task, str):
            task = make_task(task, **task_kwargs)
        elif task_kwargs:
            raise ValueError(f"task keyword arguments given with a task instance: {task_kwargs}")
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            modes = [mode.value for mode in AutoresetMode]
            raise ValueError(f"autoreset_mode {autoreset_mode!r} is not one of {modes}") from None
        if max_episode_steps is not None and max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be positive, got {max_episode_steps}")
        self.task = task
        self.num_envs = int(num_envs)
        self.max_episode_steps = max_episode_steps
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode {render_mode!r} is not one of {list(RENDER_MODES)}")
        self.metadata = {"autoreset_mode": self.autoreset_mode, "render_modes": list(RENDER_MODES)}
        self.render_mode = render_mode
        self._renderer: StateRenderer | None = None

        self.model = task.compile(integrator)
        reference = mujoco.MjData(self.model)
        task.bind(self.model, reference.qpos.ravel().copy(), reference.qvel.ravel().copy())
        self.metadata["render_fps"] = round(1 / task.dt)  # real time, as gymnasium's envs
        self.physics = make_physics(
            backend,
            self.model,
            self.num_envs,
            task.exports(self.model),
            rne_post_constraint=task.needs_rne,
            num_threads=num_threads,
            device=self.device,
            deterministic=deterministic,
        )
        self._names = list(task.exports(self.model))

        low, high = self.model.actuator_ctrlrange.copy().astype(np.float32).T
        self.single_action_space = gymnasium.spaces.Box(low=low, high=high, dtype=np.float32)
        obs_dim = task.observation(self._arrays()).shape[1]
        self.single_observation_space = gymnasium.spaces.Box(
            -np.inf, np.inf, shape=(obs_dim,), dtype=np.float64
        )
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)

        n, k = self.num_envs, task.num_feet
        self._rngs: list[np.random.Generator] | None = None
        self._position = task.position(self._arrays())
        self._elapsed = np.zeros(n, dtype=np.int64)
        self._return = np.zeros(n)
        self._contact_sum = np.zeros((n, k))
        self._needs_reset = np.zeros(n, dtype=bool)
        self._ctrl = np.zeros((n, self.model.nu))
        self._obs = np.zeros((n, obs_dim))
        self._all = np.ones(n, dtype=bool)

    @property
    def num_feet(self) -> int:
        """Number of measures k."""
        return self.task.num_feet

    def _arrays(self) -> dict[str, np.ndarray]:
        return {name: self.physics.view(name) for name in self._names}

    def _contacts(self) -> np.ndarray:
        return (self.physics.sensordata > 0).astype(np.float32)

    def _seed(self, seed: int | list[int | None] | None) -> None:
        if seed is None and self._rngs is not None:
            return
        if seed is None or isinstance(seed, int | np.integer):
            seeds = [None if seed is None else int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(
                    f"reset(seed=...) got {len(seeds)} seeds for {self.num_envs} environments"
                )
        self._rngs = [seeding.np_random(s)[0] for s in seeds]

    def seed_generators(self, seed: int | list[int | None] | None) -> None:
        """Seed the reset-noise generators as :meth:`reset` does (``None`` keeps them)."""
        self._seed(seed)

    def episode_statistics(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N,) return, (N,) length and (N, k) measures of each current or last episode.

        With autoreset disabled a finished sub-environment keeps them until it is reset:
        they are what ``info["episode"]`` reported when its episode ended.
        """
        length = np.maximum(self._elapsed, 1)
        return self._return.copy(), self._elapsed.copy(), self._contact_sum / length[:, None]

    def draw_initial_states(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, nq) positions and (n, nv) velocities of the next initial states of ``ids``.

        Each sub-environment's generator advances by one draw, as a reset of it does.
        """
        if self._rngs is None:
            raise RuntimeError("seed the generators (reset or seed_generators) first")
        qpos = np.empty((len(ids), self.model.nq))
        qvel = np.empty((len(ids), self.model.nv))
        for row, i in enumerate(ids):  # filled in place: this runs on most steps of a batch
            qpos[row], qvel[row] = self.task.reset_noise(self._rngs[i])
        return qpos, qvel

    def _reset_envs(self, ids: np.ndarray) -> None:
        """Draw initial states for sub-environments ``ids`` and reset their episode stats."""
        qpos, qvel = self.draw_initial_states(ids)
        self.physics.reset(ids, qpos, qvel)
        self._position[ids] = self.task.position(self._arrays())[ids]
        self._reset_stats(ids)

    def _reset_stats(self, ids: np.ndarray) -> None:
        """Zero the episode statistics of sub-environments ``ids`` (their physics is reset)."""
        self._elapsed[ids] = 0
        self._return[ids] = 0.0
        self._contact_sum[ids] = 0.0
        self._needs_reset[ids] = False

    def _check_actions(self, actions: Any) -> np.ndarray:
        actions = np.asarray(actions)
        expected = (self.num_envs, self.model.nu)
        if actions.shape != expected:
            raise ValueError(
                f"actions must have shape (num_envs, action_dim) = {expected}, got {actions.shape}"
            )
        if actions.dtype.kind != "f":
            raise ValueError(f"actions must be a float32 or float64 array, got {actions.dtype}")
        if not np.isfinite(actions).all():
            bad = np.flatnonzero(~np.isfinite(actions).all(axis=1))
            raise ValueError(
                f"actions contain NaN or inf for sub-environments {bad[:10].tolist()}; "
                "check the policy's outputs"
            )
        return actions

    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every sub-environment, or those in ``options["reset_mask"]``.

        Args:
            seed: an int seeds sub-environment i with ``seed + i`` (gymnasium's rule); a list
                gives one seed each; ``None`` keeps the generators' streams.
            options: ``{"reset_mask": (N,) bool}`` resets only the masked sub-environments.

        Returns:
            (N, obs_dim) observations and an info with ``foot_contact``.
        """
        self._seed(seed)
        mask = self._all if options is None else options.get("reset_mask", self._all)
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != (self.num_envs,):
            raise ValueError(f"reset_mask must have shape ({self.num_envs},), got {mask.shape}")
        self._reset_envs(np.flatnonzero(mask))
        obs = self.task.observation(self._arrays())
        self._obs[mask] = obs[mask]
        return self._obs.copy(), {"foot_contact": self._contacts(), "_foot_contact": mask.copy()}

    def step(
        self, actions: np.ndarray, mask: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Advance every sub-environment by one env step.

        Args:
            actions: (N, action_dim) float actions. Like gymnasium, values outside the
                action space are passed on: MuJoCo clamps the controls to ``ctrlrange``
                while the control cost is computed on the action as given.
            mask: (N,) bool, the sub-environments to advance (a qdil extension, only with
                ``autoreset_mode=DISABLED``); the others keep their state and report reward
                0 and no episode end. Evaluations use it to stop simulating finished
                episodes.

        Returns:
            ``(obs, reward, terminated, truncated, info)`` with (N, ...) arrays; rewards are
            the task's true rewards.

        Raises:
            ValueError: for actions of the wrong shape or dtype, or with NaN/inf.
        """
        if self._rngs is None:
            raise RuntimeError("call reset() before step()")
        actions = self._check_actions(actions)
        resetting = self._needs_reset.copy()
        stepping = ~resetting
        if mask is not None:
            if self.autoreset_mode is not AutoresetMode.DISABLED:
                raise ValueError("step(mask=...) needs autoreset_mode=DISABLED")
            mask = np.asarray(mask, dtype=bool)
            if mask.shape != (self.num_envs,):
                raise ValueError(f"mask must have shape ({self.num_envs},), got {mask.shape}")
            resetting &= mask
            stepping = mask & ~resetting
        if self.autoreset_mode is AutoresetMode.DISABLED:
            if resetting.any():
                raise RuntimeError(
                    f"sub-environments {np.flatnonzero(resetting)[:10].tolist()} finished; "
                    "reset them with reset(options={'reset_mask': mask}) or leave them out "
                    "of step(mask=...) (autoreset is DISABLED)"
                )
            resetting = np.zeros_like(resetting)
        self._ctrl[:] = actions
        # NEXT_STEP resets ride along in the step's parallel region (one launch, and the
        # arrays below already hold the reset states, as a separate reset would leave them)
        reset_ids = np.flatnonzero(resetting)
        reset = (reset_ids, *self.draw_initial_states(reset_ids)) if reset_ids.size else None
        self.physics.step(self._ctrl, self.task.frame_skip, stepping, reset=reset)
        x = self._arrays()

        position = self.task.position(x)
        velocity = (position - self._position) / self.task.dt
        self._position[stepping] = position[stepping]
        if reset is not None:
            self._position[reset_ids] = position[reset_ids]
            self._reset_stats(reset_ids)
        reward, terms = self.task.reward(velocity, actions, x)
        terminated = self.task.terminated(x) & stepping
        self._elapsed[stepping] += 1
        truncated = np.zeros(self.num_envs, dtype=bool)
        if self.max_episode_steps is not None:
            truncated = (self._elapsed >= self.max_episode_steps) & stepping
        contacts = self._contacts()
        obs = self.task.observation(x)

        info: dict[str, Any] = {}
        partial = not stepping.all()
        if partial:  # sub-environments that reset or sit out this step did not move
            reward = np.where(stepping, reward, 0.0)
        for key, value in {**terms, **self.task.info(x, velocity)}.items():
            if partial:
                value = np.where(stepping if value.ndim == 1 else stepping[:, None], value, 0.0)
            info[key] = value
            info[f"_{key}"] = stepping
        self._return[stepping] += reward[stepping]
        self._contact_sum[stepping] += contacts[stepping]
        done = terminated | truncated
        if done.any():
            length = np.maximum(self._elapsed, 1)
            info["episode"] = {
                "r": np.where(done, self._return, 0.0),
                "l": np.where(done, self._elapsed, 0),
                "measures": np.where(done[:, None], self._contact_sum / length[:, None], 0.0),
                "_r": done,
                "_l": done,
                "_measures": done,
            }
            info["_episode"] = done

        if self.autoreset_mode is AutoresetMode.SAME_STEP and done.any():
            final_info = {key: value for key, value in info.items() if key != "episode"}
            final_info["foot_contact"] = contacts.copy()
            final_info["_foot_contact"] = done
            info["final_obs"] = np.where(done[:, None], obs, 0.0)
            info["_final_obs"] = done
            info["final_info"] = final_info
            info["_final_info"] = done
            self._reset_envs(np.flatnonzero(done))
            obs[done] = self.task.observation(self._arrays())[done]
            contacts[done] = self._contacts()[done]
        elif self.autoreset_mode is AutoresetMode.NEXT_STEP:
            self._needs_reset = done
        elif self.autoreset_mode is AutoresetMode.DISABLED:
            self._needs_reset |= done
        info["foot_contact"] = contacts
        info["_foot_contact"] = self._all
        self._obs = obs
        return obs.copy(), reward, terminated, truncated, info

    def render(self) -> tuple[np.ndarray, ...] | None:
        """The first simulation's state drawn: a one-tuple of a (480, 480, 3) uint8 frame.

        Gymnasium's vector API returns a frame per sub-environment drawn; this draws the
        first only (a batch is hundreds). Reads the state, writes nothing to the simulation.

        Returns:
            ``(frame,)``, or ``None`` (with gymnasium's warning) without a render mode.
        """
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode; pass render_mode=")
            return None
        if self._renderer is None:
            task = self.task.reference_id or self.task.gym_id
            self._renderer = StateRenderer(self.model, distance=CAMERA_DISTANCE.get(task, 4.0))
        qpos, qvel = self.physics.view("qpos")[0], self.physics.view("qvel")[0]
        return (self._renderer.draw(qpos, qvel),)

    def close_extras(self, **kwargs: Any) -> None:
        """Free the renderer's OpenGL context, if :meth:`render` made one."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
