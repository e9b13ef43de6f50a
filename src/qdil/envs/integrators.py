"""The integrator a task steps with: its model file's (the v5 task), or one asked for.

``env.integrator`` replaces the model file's ``<option integrator>`` before the model is
compiled, on every backend; a run with another integrator than its task's own is not the
gymnasium task, and its name and its report's task say so (docs/guides/gpu.md#integrators).
"""

from __future__ import annotations

import functools
from pathlib import Path

import mujoco

INTEGRATORS: dict[str, mujoco.mjtIntegrator] = {
    "euler": mujoco.mjtIntegrator.mjINT_EULER,
    "rk4": mujoco.mjtIntegrator.mjINT_RK4,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
}
"""The integrators ``env.integrator`` accepts, by name, as MuJoCo's enum."""


def integrator_name(value: int | mujoco.mjtIntegrator) -> str:
    """The name (a key of :data:`INTEGRATORS`) of a model's ``opt.integrator``."""
    for name, member in INTEGRATORS.items():
        if int(member) == int(value):
            return name
    return mujoco.mjtIntegrator(int(value)).name.removeprefix("mjINT_").lower()


def check_integrator(name: str | None) -> None:
    """Refuse an integrator qdil does not step with.

    Raises:
        ValueError: naming ``env.integrator`` and the names it accepts.
    """
    if name is not None and name not in INTEGRATORS:
        raise ValueError(
            f"env.integrator must be null (the task's own) or one of {list(INTEGRATORS)}, "
            f"got {name!r}"
        )


def set_integrator(spec: mujoco.MjSpec, name: str | None) -> None:
    """Make the uncompiled model ``spec`` step with integrator ``name`` (None: keep its own)."""
    check_integrator(name)
    if name is not None:
        spec.option.integrator = INTEGRATORS[name]


@functools.cache
def own_integrator(xml_path: Path) -> str:
    """The integrator the model file at ``xml_path`` asks for (MuJoCo's default: Euler)."""
    return integrator_name(mujoco.MjSpec.from_file(str(xml_path)).option.integrator)


def changed_integrator(xml_path: Path, name: str | None) -> str | None:
    """``name`` if it differs from the model file's own integrator, else None (the v5 task)."""
    check_integrator(name)
    return None if name is None or name == own_integrator(Path(xml_path)) else name


def task_label(task: str, changed: str | None) -> str:
    """How reports name a task: ``Walker2d-v5``, or ``Walker2d-v5 (euler)`` when changed."""
    return task if changed is None else f"{task} ({changed})"
