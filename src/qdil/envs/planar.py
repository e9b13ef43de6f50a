"""The planar tasks: Walker2d, Hopper and HalfCheetah, which move in the x–z plane.

Vectorised twins of gymnasium's ``walker2d_v5.py``, ``hopper_v5.py`` and
``half_cheetah_v5.py``: same constructor arguments and defaults, same observation, reward
terms, termination and reset noise (the tests require equality step by step).
"""

from __future__ import annotations

import numpy as np
from typing_extensions import override

from qdil.envs.arrays import namespace
from qdil.envs.task_base import Arrays, HealthyTask, LocomotionTask, check_range


class _PlanarWalker(HealthyTask):
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
        self.healthy_z_range = check_range("healthy_z_range", healthy_z_range)
        self.healthy_angle_range = check_range("healthy_angle_range", healthy_angle_range)
        self.reset_noise_scale = reset_noise_scale
        self.exclude_positions = exclude_current_positions_from_observation

    @override
    def observation(self, x: Arrays) -> np.ndarray:
        xp = namespace(x["qpos"])
        position = x["qpos"][:, 1:] if self.exclude_positions else x["qpos"]
        return xp.concatenate((position, xp.clip(x["qvel"], -10, 10)), axis=1)

    @override
    def reward(
        self, velocity: np.ndarray, action: np.ndarray, x: Arrays
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        xp = namespace(action)
        forward = self.forward_reward_weight * velocity
        healthy = self.is_healthy(x) * self.healthy_reward
        ctrl_cost = self.ctrl_cost_weight * xp.sum(xp.square(action), axis=1)
        reward = forward + healthy - ctrl_cost
        return reward, {
            "reward_forward": forward,
            "reward_ctrl": -ctrl_cost,
            "reward_survive": healthy,
        }

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
        self.healthy_state_range = check_range("healthy_state_range", healthy_state_range)

    @override
    def is_healthy(self, x: Arrays) -> np.ndarray:
        qpos = x["qpos"]
        xp = namespace(qpos)
        state = xp.concatenate((qpos, x["qvel"]), axis=1)[:, 2:]
        (min_s, max_s), (min_z, max_z) = self.healthy_state_range, self.healthy_z_range
        min_angle, max_angle = self.healthy_angle_range
        z, angle = qpos[:, 1], qpos[:, 2]
        healthy_state = xp.all((min_s < state) & (state < max_s), axis=1)
        healthy_z = (min_z < z) & (z < max_z)
        healthy_angle = (min_angle < angle) & (angle < max_angle)
        return healthy_state & healthy_z & healthy_angle


class HalfCheetah(LocomotionTask):
    """Gymnasium's HalfCheetah-v5; feet ``bfoot`` (back), ``ffoot`` (front). Never terminates."""

    gym_id = "HalfCheetah-v5"
    feet = ("bfoot", "ffoot")
    default_xml = "half_cheetah.xml"
    default_frame_skip = 5
    normal_velocity_noise = True

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
        return namespace(position).concatenate((position, x["qvel"]), axis=1)

    @override
    def reward(
        self, velocity: np.ndarray, action: np.ndarray, x: Arrays
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        xp = namespace(action)
        forward = self.forward_reward_weight * velocity
        ctrl_cost = self.ctrl_cost_weight * xp.sum(xp.square(action), axis=1)
        return forward - ctrl_cost, {"reward_forward": forward, "reward_ctrl": -ctrl_cost}
