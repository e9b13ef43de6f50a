"""Batches of MuJoCo Warp worlds, and moving simulations' states between them.

A :class:`Worlds` is one ``mujoco_warp.Data`` with the buffers that save its integration
states. :func:`copy_states` moves states from some worlds of one batch to some of another:
:class:`~qdil.envs.warp_physics.WarpBatch` narrows the simulations it still steps into a
smaller batch with it (MuJoCo Warp steps every world of a ``Data``), and writes them back.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import mujoco
import torch


@dataclass(frozen=True)
class Worlds:
    """One MuJoCo Warp ``Data`` of ``size`` worlds and the buffers that save their states.

    Attributes:
        data: the ``mujoco_warp.Data``.
        saved: (size, state size) Warp float32 array of integration states.
        keep: (size,) Warp bool array: the worlds a ``set_state`` writes.
        ctrl: (size, nu) zero-copy torch view of ``data.ctrl``.
        size: worlds in ``data``.
    """

    data: Any
    saved: Any
    keep: Any
    ctrl: torch.Tensor
    size: int

    @classmethod
    def make(cls, warp: Any, mjw: Any, model: mujoco.MjModel, size: int, state: int) -> Worlds:
        """``size`` worlds of ``model`` on Warp's current device, state buffers for ``state``."""
        data = mjw.make_data(model, nworld=size)
        ctrl = warp.to_torch(data.ctrl).reshape(size, -1)
        saved = warp.zeros((size, mujoco.mj_stateSize(model, state)), dtype=float)
        return cls(data, saved, warp.zeros(size, dtype=bool), ctrl, size)

    def field(self, warp: Any, name: str) -> torch.Tensor:
        """(size, length) zero-copy torch view of the ``Data`` field ``name``."""
        return warp.to_torch(getattr(self.data, name)).reshape(self.size, -1)


def copy_states(
    warp: Any,
    mjw: Any,
    wmodel: Any,
    state: int,
    source: tuple[Worlds, torch.Tensor | slice | None],
    target: tuple[Worlds, torch.Tensor | None],
) -> None:
    """Copy integration states from worlds of one batch into worlds of another.

    The integration state is all a step reads that it does not compute afresh (time,
    positions, velocities, actuator states, controls, applied forces, the solver's warm
    start), so a world goes on from it with the same bits in either batch. Launches go on
    Warp's current stream.

    Args:
        warp: the ``warp`` module.
        mjw: the ``mujoco_warp`` module.
        wmodel: the model on the device.
        state: ``mujoco_warp.State`` flags of the state copied.
        source: a batch and the (n,) int64 indices (or a slice) of its worlds to copy
            (``None``: all).
        target: a batch and the (n,) indices of its worlds that receive them, in the same
            order (``None``: all).
    """
    (giver, picked), (taker, placed) = source, target
    mjw.get_state(wmodel, giver.data, giver.saved, state)
    states = warp.to_torch(giver.saved)
    if picked is not None:
        states = states[picked]
    if placed is None:
        warp.to_torch(taker.saved).copy_(states)
        mjw.set_state(wmodel, taker.data, taker.saved, state)
        return
    keep = warp.to_torch(taker.keep)
    keep.zero_()
    keep[placed] = True
    warp.to_torch(taker.saved)[placed] = states
    mjw.set_state(wmodel, taker.data, taker.saved, state, taker.keep)
