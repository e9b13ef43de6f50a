"""Vectorised twins of gymnasium's v5 MuJoCo locomotion tasks.

Each task states, for N simulations at once, what gymnasium's single-env class computes:
the observation, the true reward with its documented terms, termination and the reset
noise. Constructor arguments and defaults are gymnasium's (``gymnasium/envs/mujoco/*_v5.py``)
so that ``make_vec("qdil/Walker2d-v5", ctrl_cost_weight=...)`` means what it means there.
The tests step each task against gymnasium's own environment and require equality.

The foot geoms fix the measure space (decision D8): foot j's flag is 1 when the foot geom
touches the floor in the state after an env step.

The base class is in :mod:`qdil.envs.task_base`, the tasks in :mod:`qdil.envs.planar` and
:mod:`qdil.envs.spatial`; this module names them by gymnasium id.
"""

from __future__ import annotations

import inspect
from typing import Any

from qdil.envs.integrators import changed_integrator
from qdil.envs.planar import HalfCheetah, Hopper, Walker2d
from qdil.envs.spatial import Ant, Humanoid
from qdil.envs.task_base import Arrays, LocomotionTask

__all__ = [
    "TASKS",
    "VARIANTS",
    "Ant",
    "Arrays",
    "HalfCheetah",
    "Hopper",
    "Humanoid",
    "HumanoidNewton",
    "LocomotionTask",
    "Walker2d",
    "changed_for_task",
    "make_task",
]

TASKS: dict[str, type[LocomotionTask]] = {
    cls.gym_id: cls for cls in (Walker2d, HalfCheetah, Humanoid, Hopper, Ant)
}
"""The tasks equal to gymnasium's v5 tasks, by gymnasium id."""


class HumanoidNewton(Humanoid):
    """Humanoid-v5 with MuJoCo's Newton solver instead of PGS, for MuJoCo Warp.

    MuJoCo Warp has no PGS solver, which ``humanoid.xml`` asks for. Everything else
    (observation, reward, termination, reset noise) is Humanoid-v5's; the contact and joint
    limit forces are solved by Newton's method, so trajectories differ from gymnasium's once
    the feet touch the floor (docs/guides/gpu.md).
    """

    gym_id = "Humanoid-v5-newton"
    reference_id = "Humanoid-v5"
    solver = "newton"


VARIANTS: dict[str, type[LocomotionTask]] = {HumanoidNewton.gym_id: HumanoidNewton}
"""Tasks that differ from their gymnasium namesake on purpose (each documents how)."""


def make_task(name: str, **kwargs: Any) -> LocomotionTask:
    """Build a task by its gymnasium id (``"Walker2d-v5"``) with gymnasium's keyword arguments.

    Raises:
        ValueError: for an unknown task or keyword, naming the known ones.
    """
    known = TASKS | VARIANTS
    cls = known.get(name.removeprefix("qdil/"))
    if cls is None:
        raise ValueError(f"unknown task {name!r}; known tasks: {', '.join(known)}")
    try:
        return cls(**kwargs)
    except TypeError as error:
        allowed = [p for p in inspect.signature(cls).parameters]
        raise ValueError(
            f"{name}: {error}. Keyword arguments accepted: {', '.join(allowed)}"
        ) from None


def changed_for_task(task: str, task_kwargs: dict | None, name: str | None) -> str | None:
    """``env.integrator`` ``name`` if it is not the model's own of ``task``, else None.

    Raises:
        ValueError, FileNotFoundError: an unknown task or keyword, a missing model file.
    """
    if name is None:
        return None
    return changed_integrator(make_task(task, **(task_kwargs or {})).xml_path, name)
