"""The three-dimensional tasks: Humanoid and Ant, which turn and move in the plane.

Vectorised twins of gymnasium's ``humanoid_v5.py`` and ``ant_v5.py``: same constructor
arguments and defaults, same observation (including the external contact forces that need
``mj_rnePostConstraint``), reward terms, termination and reset noise.
"""

from __future__ import annotations

import mujoco
import numpy as np
from typing_extensions import override

from qdil.envs.arrays import constant, namespace
from qdil.envs.physics_base import Export
from qdil.envs.task_base import Arrays, HealthyTask, check_range


class _SpatialWalker(HealthyTask):
    """Humanoid and Ant: robots that turn, with contact forces in observation and reward."""

    needs_rne = True

    @override
    def info(self, x: Arrays, velocity: np.ndarray) -> dict[str, np.ndarray]:
        return {
            "x_position": x["qpos"][:, 0].copy(),
            "y_position": x["qpos"][:, 1].copy(),
            "x_velocity": velocity[:, 0].copy(),
            "y_velocity": velocity[:, 1].copy(),
        }


class Humanoid(_SpatialWalker):
    """Gymnasium's Humanoid-v5; feet ``right_foot``, ``left_foot``; reward has a contact cost."""

    gym_id = "Humanoid-v5"
    feet = ("right_foot", "left_foot")
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
        self.contact_cost_range = check_range("contact_cost_range", contact_cost_range)
        self.healthy_reward = healthy_reward
        self.terminate_when_unhealthy = terminate_when_unhealthy
        self.healthy_z_range = check_range("healthy_z_range", healthy_z_range)
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
        self._mass_tensors: dict = {}  # the masses on each torch device the task runs on

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
        xp = namespace(x["xipos"])
        xipos = x["xipos"].reshape(len(x["xipos"]), -1, 3)
        mass = constant(self._mass, xipos, self._mass_tensors)[:, None]
        return xp.copy((xp.sum(mass * xipos, axis=1) / xp.sum(mass))[:, 0:2])

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
        return namespace(x["qvel"]).concatenate(parts, axis=1)

    @override
    def reward(
        self, velocity: np.ndarray, action: np.ndarray, x: Arrays
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        xp = namespace(x["ctrl"])
        forward = self.forward_reward_weight * velocity[:, 0]
        healthy = self.is_healthy(x) * self.healthy_reward
        # gymnasium takes the control cost from data.ctrl, not from the action
        ctrl_cost = self.ctrl_cost_weight * xp.sum(xp.square(x["ctrl"]), axis=1)
        contact_cost = self.contact_cost_weight * xp.sum(xp.square(x["cfrc_ext"]), axis=1)
        contact_cost = xp.clip(contact_cost, *self.contact_cost_range)
        reward = forward + healthy - (ctrl_cost + contact_cost)
        return reward, {
            "reward_survive": healthy,
            "reward_forward": forward,
            "reward_ctrl": -ctrl_cost,
            "reward_contact": -contact_cost,
        }


class Ant(_SpatialWalker):
    """Gymnasium's Ant-v5; four feet, the ankle geoms; reward has a contact cost."""

    gym_id = "Ant-v5"
    feet = ("left_ankle_geom", "right_ankle_geom", "third_ankle_geom", "fourth_ankle_geom")
    default_xml = "ant.xml"
    default_frame_skip = 5
    normal_velocity_noise = True

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
        self.healthy_z_range = check_range("healthy_z_range", healthy_z_range)
        self.contact_force_range = check_range("contact_force_range", contact_force_range)
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
        xp = namespace(x["qpos"])
        state = xp.concatenate((x["qpos"], x["qvel"]), axis=1)
        min_z, max_z = self.healthy_z_range
        z = x["qpos"][:, 2]
        return xp.all(xp.isfinite(state), axis=1) & (min_z <= z) & (z <= max_z)

    @override
    def observation(self, x: Arrays) -> np.ndarray:
        xp = namespace(x["qpos"])
        parts = [x["qpos"][:, 2:] if self.exclude_positions else x["qpos"], x["qvel"]]
        if self.include_cfrc_ext:
            parts.append(xp.clip(x["cfrc_ext"], *self.contact_force_range)[:, 6:])
        return xp.concatenate(parts, axis=1)

    @override
    def reward(
        self, velocity: np.ndarray, action: np.ndarray, x: Arrays
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        xp = namespace(action)
        forward = velocity[:, 0] * self.forward_reward_weight
        healthy = self.is_healthy(x) * self.healthy_reward
        ctrl_cost = self.ctrl_cost_weight * xp.sum(xp.square(action), axis=1)
        forces = xp.clip(x["cfrc_ext"], *self.contact_force_range)
        contact_cost = self.contact_cost_weight * xp.sum(xp.square(forces), axis=1)
        reward = forward + healthy - (ctrl_cost + contact_cost)
        return reward, {
            "reward_forward": forward,
            "reward_ctrl": -ctrl_cost,
            "reward_contact": -contact_cost,
            "reward_survive": healthy,
        }
