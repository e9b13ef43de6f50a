"""Vectorised twins of gymnasium's v5 MuJoCo locomotion tasks.

Each task states, for N simulations at once, what gymnasium's single-env class computes:
the observation, the true reward with its documented terms, termination and the reset
noise. Constructor arguments and defaults are gymnasium's (``gymnasium/envs/mujoco/*_v5.py``)
so that ``make_vec("qdil/Walker2d-v5", ctrl_cost_weight=...)`` means what it means there.
The tests step each task against gymnasium's own environment and require equality.

The foot geoms fix the measure space (decision D8): foot j's flag is 1 when the foot geom
touches the floor in the state after an env step.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import gymnasium
import mujoco
import numpy as np
from typing_extensions import override

from qdil.envs.physics import Export

_ASSETS = Path(gymnasium.__file__).parent / "envs" / "mujoco" / "assets"

Arrays = Mapping[str, np.ndarray]


class LocomotionTask(abc.ABC):
    """What one gymnasium v5 locomotion task computes, vectorised over N simulations.

    Subclasses declare the ``MjData`` slices they read (:meth:`exports`), and compute the
    observation, reward and termination from those (N, ...) arrays.

    Attributes:
        gym_id: the gymnasium task this one equals, e.g. ``"Walker2d-v5"``.
        feet: foot geom names in measure order.
        floor: the floor geom name.
        needs_rne: whether gymnasium's observation or reward reads ``cfrc_ext``, which needs
            ``mj_rnePostConstraint`` after each step.
    """

    gym_id: ClassVar[str]
    feet: ClassVar[tuple[str, ...]]
    floor: ClassVar[str] = "floor"
    needs_rne: ClassVar[bool] = False
    default_xml: ClassVar[str]
    default_frame_skip: ClassVar[int]

    def __init__(self, xml_file: str | None, frame_skip: int | None) -> None:
        xml = self.default_xml if xml_file is None else xml_file
        path = Path(xml) if Path(xml).is_absolute() or Path(xml).exists() else _ASSETS / xml
        if not path.exists():
            raise FileNotFoundError(f"xml_file {xml!r}: no such file (looked at {path})")
        self.xml_path = path
        self.frame_skip = self.default_frame_skip if frame_skip is None else int(frame_skip)
        if self.frame_skip < 1:
            raise ValueError(f"frame_skip must be at least 1, got {frame_skip}")

    def bind(self, model: mujoco.MjModel, init_qpos: np.ndarray, init_qvel: np.ndarray) -> None:
        """Remember the compiled model's constants the formulas need."""
        self.model = model
        self.dt = model.opt.timestep * self.frame_skip
        self.init_qpos = init_qpos.copy()
        self.init_qvel = init_qvel.copy()

    @property
    def num_feet(self) -> int:
        """Number of measures k."""
        return len(self.feet)

    def exports(self, model: mujoco.MjModel) -> dict[str, Export]:
        """``MjData`` slices read after each step; ``qpos`` and ``qvel`` are always there."""
        return {"qpos": Export("qpos"), "qvel": Export("qvel")}

    def position(self, x: Arrays) -> np.ndarray:
        """(N,) x position, or (N, 2) xy position, whose finite difference is the velocity."""
        return x["qpos"][:, 0].copy()

    @abc.abstractmethod
    def observation(self, x: Arrays) -> np.ndarray:
        """(N, obs_dim) float64 observation from the exported arrays."""

    @abc.abstractmethod
    def reward(
        self, velocity: np.ndarray, action: np.ndarray, x: Arrays
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """(N,) true reward and its terms (gymnasium's ``reward_*`` info keys).

        Args:
            velocity: (N,) or (N, 2) velocity of :meth:`position` over the env step.
            action: (N, action_dim) actions as given to the environment.
            x: the exported post-step arrays.
        """

    def terminated(self, x: Arrays) -> np.ndarray:
        """(N,) bool: the episode ends because the robot is unhealthy."""
        return np.zeros(len(x["qpos"]), dtype=bool)

    def info(self, x: Arrays, velocity: np.ndarray) -> dict[str, np.ndarray]:
        """Per-step diagnostics beside the reward terms."""
        return {"x_position": x["qpos"][:, 0].copy(), "x_velocity": velocity}

    def reset_noise(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """One initial state (qpos, qvel), drawn exactly as gymnasium's ``reset_model``."""
        low, high = -self.reset_noise_scale, self.reset_noise_scale
        qpos = self.init_qpos + rng.uniform(low=low, high=high, size=self.model.nq)
        qvel = self.init_qvel + rng.uniform(low=low, high=high, size=self.model.nv)
        return qpos, qvel

    reset_noise_scale: float


def _check_range(name: str, value: tuple[float, float]) -> tuple[float, float]:
    low, high = value
    if not low <= high:
        raise ValueError(f"{name} must be (low, high) with low <= high, got {value}")
    return (float(low), float(high))


class _PlanarWalker(LocomotionTask):
    """Walker2d and Hopper: planar robots with a healthy reward and clipped velocities."""

    def __init__(
        self,
        xml_file: str | None,
        frame_skip: int | None,
        forward_reward_weight: float,
        ctrl_cost_weight: float,
        healthy_reward: float,
        terminate_when_unhealthy: bool,
        healthy_z_range: tuple[float, float],
        healthy_angle_range: tuple[float, float],
        reset_noise_scale: float,
        exclude_current_positions_from_observation: bool,
    ) -> None:
        super().__init__(xml_file, frame_skip)
        self.forward_reward_weight = forward_reward_weight
        self.ctrl_cost_weight = ctrl_cost_weight
        self.healthy_reward = healthy_reward
        self.terminate_when_unhealthy = terminate_when_unhealthy
        self.healthy_z_range = _check_range("healthy_z_range", healthy_z_range)
        self.healthy_angle_range = _check_range("healthy_angle_range", healthy_angle_range)
        self.reset_noise_scale = reset_noise_scale
        self.exclude_positions = exclude_current_positions_from_observation

    @override
    def observation(self, x: Arrays) -> np.ndarray:
        position = x["qpos"][:, 1:] if self.exclude_positions else x["qpos"]
        return np.concatenate((position, np.clip(x["qvel"], -10, 10)), axis=1)

    @abc.abstractmethod
    def is_healthy(self, x: Arrays) -> np.ndarray:
        """(N,) bool health test."""

    @override
    def reward(
        self, velocity: np.ndarray, action: np.ndarray, x: Arrays
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        forward = self.forward_reward_weight * velocity
        healthy = self.is_healthy(x) * self.healthy_reward
        ctrl_cost = self.ctrl_cost_weight * np.sum(np.square(action), axis=1)
        reward = forward + healthy - ctrl_cost
        return reward, {
            "reward_forward": forward,
            "reward_ctrl": -ctrl_cost,
            "reward_survive": healthy,
        }

    @override
    def terminated(self, x: Arrays) -> np.ndarray:
        return ~self.is_healthy(x) & self.terminate_when_unhealthy

    @override
    def info(self, x: Arrays, velocity: np.ndarray) -> dict[str, np.ndarray]:
        return {
            **super().info(x, velocity),
            "z_distance_from_origin": x["qpos"][:, 1] - self.init_qpos[1],
        }


class Walker2d(_PlanarWalker):
    """Gymnasium's Walker2d-v5; feet ``foot_geom`` (right), ``foot_left_geom`` (left)."""

    gym_id = "Walker2d-v5"
    feet = ("foot_geom", "foot_left_geom")
    default_xml = "walker2d_v5.xml"
    default_frame_skip = 4

    def __init__(
        self,
        xml_file: str | None = None,
        frame_skip: int | None = None,
        forward_reward_weight: float = 1.0,
        ctrl_cost_weight: float = 1e-3,
        healthy_reward: float = 1.0,
        terminate_when_unhealthy: bool = True,
        healthy_z_range: tuple[float, float] = (0.8, 2.0),
        healthy_angle_range: tuple[float, float] = (-1.0, 1.0),
        reset_noise_scale: float = 5e-3,
        exclude_current_positions_from_observation: bool = True,
    ) -> None:
        super().__init__(
            xml_file,
            frame_skip,
            forward_reward_weight,
            ctrl_cost_weight,
            healthy_reward,
            terminate_when_unhealthy,
            healthy_z_range,
            healthy_angle_range,
            reset_noise_scale,
            exclude_current_positions_from_observation,
        )

    @override
    def is_healthy(self, x: Arrays) -> np.ndarray:
        z, angle = x["qpos"][:, 1], x["qpos"][:, 2]
        (min_z, max_z), (min_angle, max_angle) = self.healthy_z_range, self.healthy_angle_range
        return (min_z < z) & (z < max_z) & (min_angle < angle) & (angle < max_angle)


class Hopper(_PlanarWalker):
    """Gymnasium's Hopper-v5; one foot, ``foot_geom``."""

    gym_id = "Hopper-v5"
    feet = ("foot_geom",)
    default_xml = "hopper.xml"
    default_frame_skip = 4

    def __init__(
        self,
        xml_file: str | None = None,
        frame_skip: int | None = None,
        forward_reward_weight: float = 1.0,
        ctrl_cost_weight: float = 1e-3,
        healthy_reward: float = 1.0,
        terminate_when_unhealthy: bool = True,
        healthy_state_range: tuple[float, float] = (-100.0, 100.0),
        healthy_z_range: tuple[float, float] = (0.7, float("inf")),
        healthy_angle_range: tuple[float, float] = (-0.2, 0.2),
        reset_noise_scale: float = 5e-3,
        exclude_current_positions_from_observation: bool = True,
    ) -> None:
        super().__init__(
            xml_file,
            frame_skip,
            forward_reward_weight,
            ctrl_cost_weight,
            healthy_reward,
            terminate_when_unhealthy,
            healthy_z_range,
            healthy_angle_range,
            reset_noise_scale,
            exclude_current_positions_from_observation,
        )
        self.healthy_state_range = _check_range("healthy_state_range", healthy_state_range)

    @override
    def is_healthy(self, x: Arrays) -> np.ndarray:
        qpos = x["qpos"]
        state = np.concatenate((qpos, x["qvel"]), axis=1)[:, 2:]
        (min_s, max_s), (min_z, max_z) = self.healthy_state_range, self.healthy_z_range
        min_angle, max_angle = self.healthy_angle_range
        z, angle = qpos[:, 1], qpos[:, 2]
        healthy_state = np.all((min_s < state) & (state < max_s), axis=1)
        healthy_z = (min_z < z) & (z < max_z)
        healthy_angle = (min_angle < angle) & (angle < max_angle)
        return healthy_state & healthy_z & healthy_angle


class HalfCheetah(LocomotionTask):
    """Gymnasium's HalfCheetah-v5; feet ``bfoot`` (back), ``ffoot`` (front). Never terminates."""

    gym_id = "HalfCheetah-v5"
    feet = ("bfoot", "ffoot")
    default_xml = "half_cheetah.xml"
    default_frame_skip = 5

    def __init__(
        self,
        xml_file: str | None = None,
        frame_skip: int | None = None,
        forward_reward_weight: float = 1.0,
        ctrl_cost_weight: float = 0.1,
        reset_noise_scale: float = 0.1,
        exclude_current_positions_from_observation: bool = True,
    ) -> None:
        super().__init__(xml_file, frame_skip)
        self.forward_reward_weight = forward_reward_weight
        self.ctrl_cost_weight = ctrl_cost_weight
        self.reset_noise_scale = reset_noise_scale
        self.exclude_positions = exclude_current_positions_from_observation

    @override
    def observation(self, x: Arrays) -> np.ndarray:
        position = x["qpos"][:, 1:] if self.exclude_positions else x["qpos"]
        return np.concatenate((position, x["qvel"]), axis=1)

    @override
    def reward(
        self, velocity: np.ndarray, action: np.ndarray, x: Arrays
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        forward = self.forward_reward_weight * velocity
        ctrl_cost = self.ctrl_cost_weight * np.sum(np.square(action), axis=1)
        return forward - ctrl_cost, {"reward_forward": forward, "reward_ctrl": -ctrl_cost}

    @override
    def reset_noise(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        low, high = -self.reset_noise_scale, self.reset_noise_scale
        qpos = self.init_qpos + rng.uniform(low=low, high=high, size=self.model.nq)
        qvel = self.init_qvel + self.reset_noise_scale * rng.standard_normal(self.model.nv)
        return qpos, qvel


class Humanoid(LocomotionTask):
    """Gymnasium's Humanoid-v5; feet ``right_foot``, ``left_foot``; reward has a contact cost."""

    gym_id = "Humanoid-v5"
    feet = ("right_foot", "left_foot")
    needs_rne = True
    default_xml = "humanoid.xml"
    default_frame_skip = 5

    def __init__(
        self,
        xml_file: str | None = None,
        frame_skip: int | None = None,
        forward_reward_weight: float = 1.25,
        ctrl_cost_weight: float = 0.1,
        contact_cost_weight: float = 5e-7,
        contact_cost_range: tuple[float, float] = (-np.inf, 10.0),
        healthy_reward: float = 5.0,
        terminate_when_unhealthy: bool = True,
        healthy_z_range: tuple[float, float] = (1.0, 2.0),
        reset_noise_scale: float = 1e-2,
        exclude_current_positions_from_observation: bool = True,
        include_cinert_in_observation: bool = True,
        include_cvel_in_observation: bool = True,
        include_qfrc_actuator_in_observation: bool = True,
        include_cfrc_ext_in_observation: bool = True,
    ) -> None:
        super().__init__(xml_file, frame_skip)
        self.forward_reward_weight = forward_reward_weight
        self.ctrl_cost_weight = ctrl_cost_weight
        self.contact_cost_weight = contact_cost_weight
        self.contact_cost_range = _check_range("contact_cost_range", contact_cost_range)
        self.healthy_reward = healthy_reward
        self.terminate_when_unhealthy = terminate_when_unhealthy
        self.healthy_z_range = _check_range("healthy_z_range", healthy_z_range)
        self.reset_noise_scale = reset_noise_scale
        self.exclude_positions = exclude_current_positions_from_observation
        self.include = {
            "cinert": include_cinert_in_observation,
            "cvel": include_cvel_in_observation,
            "qfrc_actuator": include_qfrc_actuator_in_observation,
            "cfrc_ext": include_cfrc_ext_in_observation,
        }

    @override
    def bind(self, model: mujoco.MjModel, init_qpos: np.ndarray, init_qvel: np.ndarray) -> None:
        super().bind(model, init_qpos, init_qvel)
        self._mass = model.body_mass.copy()

    @override
    def exports(self, model: mujoco.MjModel) -> dict[str, Export]:
        return {
            **super().exports(model),
            "cinert": Export("cinert", 10),  # [1:] drops the world body
            "cvel": Export("cvel", 6),
            "qfrc_actuator": Export("qfrc_actuator", 6),  # [6:] drops the free joint
            "cfrc_ext": Export("cfrc_ext"),  # all bodies: the contact cost sums them all
            "ctrl": Export("ctrl"),
            "xipos": Export("xipos"),
        }

    @override
    def position(self, x: Arrays) -> np.ndarray:
        # gymnasium's mass_center(): body masses times body CoM positions
        xipos = x["xipos"].reshape(len(x["xipos"]), -1, 3)
        mass = self._mass[:, None]
        return (np.sum(mass * xipos, axis=1) / np.sum(mass))[:, 0:2].copy()

    @override
    def is_healthy(self, x: Arrays) -> np.ndarray:
        min_z, max_z = self.healthy_z_range
        return (min_z < x["qpos"][:, 2]) & (x["qpos"][:, 2] < max_z)

    @override
    def observation(self, x: Arrays) -> np.ndarray:
        parts = [x["qpos"][:, 2:] if self.exclude_positions else x["qpos"], x["qvel"]]
        for name in ("cinert", "cvel", "qfrc_actuator"):
            if self.include[name]:
                parts.append(x[name])
        if self.include["cfrc_ext"]:
            parts.append(x["cfrc_ext"][:, 6:])
        return np.concatenate(parts, axis=1)

    @override
    def reward(
        self, velocity: np.ndarray, action: np.ndarray, x: Arrays
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        forward = self.forward_reward_weight * velocity[:, 0]
        healthy = self.is_healthy(x) * self.healthy_reward
        # gymnasium takes the control cost from data.ctrl, not from the action
        ctrl_cost = self.ctrl_cost_weight * np.sum(np.square(x["ctrl"]), axis=1)
        contact_cost = self.contact_cost_weight * np.sum(np.square(x["cfrc_ext"]), axis=1)
        contact_cost = np.clip(contact_cost, *self.contact_cost_range)
        reward = forward + healthy - (ctrl_cost + contact_cost)
        return reward, {
            "reward_survive": healthy,
            "reward_forward": forward,
            "reward_ctrl": -ctrl_cost,
            "reward_contact": -contact_cost,
        }

    @override
    def terminated(self, x: Arrays) -> np.ndarray:
        return ~self.is_healthy(x) & self.terminate_when_unhealthy

    @override
    def info(self, x: Arrays, velocity: np.ndarray) -> dict[str, np.ndarray]:
        return {
            "x_position": x["qpos"][:, 0].copy(),
            "y_position": x["qpos"][:, 1].copy(),
            "x_velocity": velocity[:, 0].copy(),
            "y_velocity": velocity[:, 1].copy(),
        }


class Ant(LocomotionTask):
    """Gymnasium's Ant-v5; four feet, the ankle geoms; reward has a contact cost."""

    gym_id = "Ant-v5"
    feet = ("left_ankle_geom", "right_ankle_geom", "third_ankle_geom", "fourth_ankle_geom")
    needs_rne = True
    default_xml = "ant.xml"
    default_frame_skip = 5

    def __init__(
        self,
        xml_file: str | None = None,
        frame_skip: int | None = None,
        forward_reward_weight: float = 1.0,
        ctrl_cost_weight: float = 0.5,
        contact_cost_weight: float = 5e-4,
        healthy_reward: float = 1.0,
        main_body: int | str = 1,
        terminate_when_unhealthy: bool = True,
        healthy_z_range: tuple[float, float] = (0.2, 1.0),
        contact_force_range: tuple[float, float] = (-1.0, 1.0),
        reset_noise_scale: float = 0.1,
        exclude_current_positions_from_observation: bool = True,
        include_cfrc_ext_in_observation: bool = True,
    ) -> None:
        super().__init__(xml_file, frame_skip)
        self.forward_reward_weight = forward_reward_weight
        self.ctrl_cost_weight = ctrl_cost_weight
        self.contact_cost_weight = contact_cost_weight
        self.healthy_reward = healthy_reward
        self.main_body = main_body
        self.terminate_when_unhealthy = terminate_when_unhealthy
        self.healthy_z_range = _check_range("healthy_z_range", healthy_z_range)
        self.contact_force_range = _check_range("contact_force_range", contact_force_range)
        self.reset_noise_scale = reset_noise_scale
        self.exclude_positions = exclude_current_positions_from_observation
        self.include_cfrc_ext = include_cfrc_ext_in_observation

    @override
    def exports(self, model: mujoco.MjModel) -> dict[str, Export]:
        body = model.body(self.main_body).id
        return {
            **super().exports(model),
            "cfrc_ext": Export("cfrc_ext"),
            "body_xy": Export("xpos", 3 * body, 3 * body + 2),
        }

    @override
    def position(self, x: Arrays) -> np.ndarray:
        return x["body_xy"].copy()

    @override
    def is_healthy(self, x: Arrays) -> np.ndarray:
        state = np.concatenate((x["qpos"], x["qvel"]), axis=1)
        min_z, max_z = self.healthy_z_range
        z = x["qpos"][:, 2]
        return np.isfinite(state).all(axis=1) & (min_z <= z) & (z <= max_z)

    @override
    def observation(self, x: Arrays) -> np.ndarray:
        parts = [x["qpos"][:, 2:] if self.exclude_positions else x["qpos"], x["qvel"]]
        if self.include_cfrc_ext:
            parts.append(np.clip(x["cfrc_ext"], *self.contact_force_range)[:, 6:])
        return np.concatenate(parts, axis=1)

    @override
    def reward(
        self, velocity: np.ndarray, action: np.ndarray, x: Arrays
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        forward = velocity[:, 0] * self.forward_reward_weight
        healthy = self.is_healthy(x) * self.healthy_reward
        ctrl_cost = self.ctrl_cost_weight * np.sum(np.square(action), axis=1)
        forces = np.clip(x["cfrc_ext"], *self.contact_force_range)
        contact_cost = self.contact_cost_weight * np.sum(np.square(forces), axis=1)
        reward = forward + healthy - (ctrl_cost + contact_cost)
        return reward, {
            "reward_forward": forward,
            "reward_ctrl": -ctrl_cost,
            "reward_contact": -contact_cost,
            "reward_survive": healthy,
        }

    @override
    def terminated(self, x: Arrays) -> np.ndarray:
        return ~self.is_healthy(x) & self.terminate_when_unhealthy

    @override
    def reset_noise(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        low, high = -self.reset_noise_scale, self.reset_noise_scale
        qpos = self.init_qpos + rng.uniform(low=low, high=high, size=self.model.nq)
        qvel = self.init_qvel + self.reset_noise_scale * rng.standard_normal(self.model.nv)
        return qpos, qvel

    @override
    def info(self, x: Arrays, velocity: np.ndarray) -> dict[str, np.ndarray]:
        return {
            "x_position": x["qpos"][:, 0].copy(),
            "y_position": x["qpos"][:, 1].copy(),
            "x_velocity": velocity[:, 0].copy(),
            "y_velocity": velocity[:, 1].copy(),
        }


TASKS: dict[str, type[LocomotionTask]] = {
    cls.gym_id: cls for cls in (Walker2d, HalfCheetah, Humanoid, Hopper, Ant)
}


def make_task(name: str, **kwargs: Any) -> LocomotionTask:
    """Build a task by its gymnasium id (``"Walker2d-v5"``) with gymnasium's keyword arguments.

    Raises:
        ValueError: for an unknown task or keyword, naming the known ones.
    """
    cls = TASKS.get(name.removeprefix("qdil/"))
    if cls is None:
        raise ValueError(f"unknown task {name!r}; known tasks: {', '.join(TASKS)}")
    try:
        return cls(**kwargs)
    except TypeError as error:
        import inspect

        allowed = [p for p in inspect.signature(cls).parameters]
        raise ValueError(
            f"{name}: {error}. Keyword arguments accepted: {', '.join(allowed)}"
        ) from None
