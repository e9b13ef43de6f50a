"""What a physics engine offers the tasks: a batch of simulations and the data copied out.

:class:`PhysicsBatch` is the seam below the tasks. The C engine
(:class:`~qdil.envs.physics.MujocoBatch`) and MuJoCo Warp
(:class:`~qdil.envs.warp_physics.WarpBatch`) each step ``num_sims`` simulations of one model
and copy the :class:`Export` slices of their data into :attr:`PhysicsBatch.exported` after
every step and reset, so the tasks and the vector environment run unchanged on either.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass

import mujoco
import numpy as np


@dataclass(frozen=True)
class Export:
    """A slice of a flat ``MjData`` field copied out after every step and reset.

    Attributes:
        field: ``MjData`` attribute name, e.g. ``"qpos"`` or ``"cfrc_ext"``.
        start: first element of the flattened field.
        stop: one past the last element; ``None`` for the end of the field.
    """

    field: str
    start: int = 0
    stop: int | None = None


def export_bounds(probe: mujoco.MjData, exports: dict[str, Export]) -> list[tuple[str, int, int]]:
    """(field, start, stop) of each export in the flattened ``MjData`` field, validated.

    Raises:
        ValueError: if an export names an unknown field or a slice outside it.
    """
    bounds = []
    for name, export in exports.items():
        if not hasattr(probe, export.field):
            raise ValueError(f"export {name!r}: MjData has no field {export.field!r}")
        size = np.asarray(getattr(probe, export.field)).size
        stop = size if export.stop is None else export.stop
        if not 0 <= export.start < stop <= size:
            raise ValueError(
                f"export {name!r}: [{export.start}:{stop}] is outside {export.field} of size {size}"
            )
        bounds.append((export.field, export.start, stop))
    return bounds


def export_slices(bounds: list[tuple[str, int, int]], names: list[str]) -> dict[str, slice]:
    """The columns of each named export in the concatenated (N, E) export array."""
    slices, width = {}, 0
    for name, (_, start, stop) in zip(names, bounds, strict=True):
        slices[name] = slice(width, width + stop - start)
        width += stop - start
    return slices


def reset_ids(
    reset: tuple[np.ndarray, np.ndarray, np.ndarray] | None, active: np.ndarray | None
) -> np.ndarray | None:
    """The (n,) int64 ids of a step's ``reset=(ids, qpos, qvel)``, or ``None`` if it has none.

    Raises:
        ValueError: if a simulation to reset is also active in the step.
    """
    if reset is None or not len(reset[0]):
        return None
    ids = np.asarray(reset[0], dtype=np.int64)
    if active is None or np.asarray(active)[ids].any():
        raise ValueError("step(reset=...) resets simulations that are also active")
    return ids


class PhysicsBatch(abc.ABC):
    """``num_sims`` simulations of one model, advanced together, and what the tasks read.

    Args:
        model: the compiled model; shared read-only by all simulations.
        num_sims: number of simulations N.
        exports: ``MjData`` slices to copy into :attr:`exported` after every step and reset,
            keyed by a name of the caller's choosing.

    Attributes:
        exported: (N, E) float64 array; :meth:`view` returns the slice of one export.
        sensordata: (N, nsensordata) float64 array of sensor values at the current states.

    Raises:
        ValueError: if ``num_sims`` is below 1 or an export names an unknown field or a
            slice outside it.
    """

    def __init__(self, model: mujoco.MjModel, num_sims: int, exports: dict[str, Export]) -> None:
        if num_sims < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_sims}")
        self.model = model
        self.num_sims = num_sims
        self._bounds = export_bounds(mujoco.MjData(model), exports)
        self._slices = export_slices(self._bounds, list(exports))
        width = sum(stop - start for _, start, stop in self._bounds)
        self.exported = np.zeros((num_sims, width))
        self.sensordata = np.zeros((num_sims, model.nsensordata))

    @property
    def slices(self) -> dict[str, slice]:
        """The columns of :attr:`exported` of each export."""
        return dict(self._slices)

    def view(self, name: str) -> np.ndarray:
        """The (N, length) columns of :attr:`exported` that hold export ``name``."""
        return self.exported[:, self._slices[name]]

    @abc.abstractmethod
    def step(
        self,
        ctrl: np.ndarray,
        nstep: int,
        active: np.ndarray | None = None,
        reset: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> None:
        """Set controls and advance the active simulations by ``nstep`` substeps.

        Args:
            ctrl: (N, nu) float64 C-contiguous controls.
            nstep: number of MuJoCo steps (the task's frame skip).
            active: (N,) bool mask of simulations to step; ``None`` for all. The others
                keep their states.
            reset: ``(ids, qpos, qvel)`` as :meth:`reset` takes them: simulations to reset
                in the same call instead of stepping (they must not be active); the result
                is that of :meth:`reset` then :meth:`step`.
        """

    @abc.abstractmethod
    def reset(self, ids: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> None:
        """Reset simulations ``ids`` to the given states, as gymnasium's ``set_state``.

        Args:
            ids: (n,) int64 indices of the simulations to reset.
            qpos: (n, nq) float64 positions.
            qvel: (n, nv) float64 velocities.
        """
