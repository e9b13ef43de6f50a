"""The base of every locomotion task: what one gymnasium v5 task computes, for N simulations.

:class:`LocomotionTask` fixes the interface the vector environment drives (the ``MjData``
slices to export, observation, reward, termination, reset noise), and :class:`HealthyTask`
the termination of the robots that can fall; the tasks themselves are in
:mod:`qdil.envs.planar` (Walker2d, Hopper, HalfCheetah) and :mod:`qdil.envs.spatial`
(Humanoid, Ant), and :mod:`qdil.envs.tasks` names them.
"""

from __future__ import annotations

import abc
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import ClassVar

import gymnasium
import mujoco
import numpy as np
from typing_extensions import override

from qdil.envs.arrays import namespace
from qdil.envs.integrators import set_integrator
from qdil.envs.physics_base import Export

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
        solver: a constraint solver that replaces the model file's (``"newton"``, ``"cg"``,
            ``"pgs"``), or ``None`` to keep it.
        reference_id: for a variant that differs from gymnasium on purpose, the gymnasium
            task it derives from (same spaces); ``None`` for the tasks equal to gymnasium's.
        normal_velocity_noise: whether gymnasium's ``reset_model`` draws the initial
            velocities from a scaled standard normal (HalfCheetah, Ant) rather than uniformly.
    """

    gym_id: ClassVar[str]
    feet: ClassVar[tuple[str, ...]]
    floor: ClassVar[str] = "floor"
    needs_rne: ClassVar[bool] = False
    solver: ClassVar[str | None] = None  # None: the model file's constraint solver
    reference_id: ClassVar[str | None] = None  # a variant's gymnasium namesake
    normal_velocity_noise: ClassVar[bool] = False
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

    def compile(self, integrator: str | None = None) -> mujoco.MjModel:
        """The task's model: a contact sensor per foot, the task's solver, ``integrator``.

        Args:
            integrator: a name of :data:`qdil.envs.integrators.INTEGRATORS` in place of the
                model file's, or ``None`` to keep it (the gymnasium task).
        """
        from qdil.envs.physics import add_contact_sensors  # numba and torch: only to build

        spec = mujoco.MjSpec.from_file(str(self.xml_path))
        add_contact_sensors(spec, self.feet, self.floor)
        if self.solver is not None:
            spec.option.solver = getattr(mujoco.mjtSolver, f"mjSOL_{self.solver.upper()}")
        set_integrator(spec, integrator)
        with warnings.catch_warnings():  # half_cheetah.xml's deprecated settotalmass
            warnings.simplefilter("ignore")
            return spec.compile()

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
        return namespace(x["qpos"]).copy(x["qpos"][:, 0])

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
        return namespace(x["qpos"]).zeros_like(x["qpos"][:, 0], dtype=bool)

    def info(self, x: Arrays, velocity: np.ndarray) -> dict[str, np.ndarray]:
        """Per-step diagnostics beside the reward terms."""
        return {"x_position": x["qpos"][:, 0].copy(), "x_velocity": velocity}

    def reset_noise(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """One initial state (qpos, qvel), drawn exactly as gymnasium's ``reset_model``."""
        low, high = -self.reset_noise_scale, self.reset_noise_scale
        qpos = self.init_qpos + rng.uniform(low=low, high=high, size=self.model.nq)
        if self.normal_velocity_noise:
            qvel = self.init_qvel + self.reset_noise_scale * rng.standard_normal(self.model.nv)
        else:
            qvel = self.init_qvel + rng.uniform(low=low, high=high, size=self.model.nv)
        return qpos, qvel

    reset_noise_scale: float


class HealthyTask(LocomotionTask):
    """A task whose episode ends when the robot leaves its healthy states.

    Gymnasium's Walker2d, Hopper, Humanoid and Ant: :meth:`terminated` is ``not healthy``
    where the task's ``terminate_when_unhealthy`` option is set.
    """

    terminate_when_unhealthy: bool

    @abc.abstractmethod
    def is_healthy(self, x: Arrays) -> np.ndarray:
        """(N,) bool health test."""

    @override
    def terminated(self, x: Arrays) -> np.ndarray:
        return ~self.is_healthy(x) & self.terminate_when_unhealthy


def check_range(name: str, value: tuple[float, float]) -> tuple[float, float]:
    """``value`` as a float (low, high) range, or a ValueError naming the keyword."""
    low, high = value
    if not low <= high:
        raise ValueError(f"{name} must be (low, high) with low <= high, got {value}")
    return (float(low), float(high))
