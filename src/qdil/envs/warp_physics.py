"""Many MuJoCo simulations of one model on MuJoCo Warp (GPU, or Warp's CPU device).

:class:`WarpBatch` is the MuJoCo Warp twin of :class:`~qdil.envs.physics.MujocoBatch`: the
same constructor, :attr:`exported` and :attr:`sensordata` arrays, :meth:`view`,
:meth:`step` and :meth:`reset`, so that :class:`~qdil.envs.vector.LocomotionVectorEnv` and
everything above it run unchanged on either engine (``env.backend: warp``). All worlds live in
one ``mujoco_warp.Data`` on the Warp device; :attr:`torch_exported` and
:attr:`torch_sensordata` are their torch tensors on that device, and the numpy arrays are
host copies made once per step for gymnasium's API.

What differs from the C engine, and why the results agree only within a tolerance
(``tests/envs/test_warp_backend.py`` states it):

- MuJoCo Warp computes in float32 (the C engine in float64);
- it has no PGS solver: a model that asks for PGS (gymnasium's Humanoid) must be switched to
  Newton by the caller, which changes its dynamics (the ``Humanoid-v5-newton`` task);
- it steps every world in each call. A world left out of ``step(active=...)`` is restored to
  its state from before the call, so it keeps its state as in :class:`MujocoBatch`.

Foot contacts are evaluated at the new state after each step exactly as the C engine does
it: kinematics, collision detection and the position-stage sensors (MuJoCo ``contact``
sensors added by :func:`~qdil.envs.physics.add_contact_sensors`).
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
import torch

from qdil.envs.physics import Export, export_bounds, export_slices


def import_warp() -> tuple[Any, Any]:
    """``(warp, mujoco_warp)``, or an ImportError that says how to install them."""
    try:
        import warp

        warp.config.quiet = True  # before mujoco_warp's import initialises Warp (banner)
        warp.config.log_level = warp.LOG_WARNING  # no line per kernel module loaded
        import mujoco_warp
    except ImportError as error:
        raise ImportError(
            "env.backend: warp needs MuJoCo Warp; install it with "
            '`pip install -e ".[warp]"` (mujoco-warp and warp-lang)'
        ) from error
    return warp, mujoco_warp


def warp_device(device: str) -> str:
    """The Warp device for ``env.device``; a clear error where it does not exist.

    Args:
        device: ``"cpu"``, ``"cuda"`` or ``"cuda:N"``.

    Raises:
        ValueError: naming ``env.device`` if the device is unknown or absent.
    """
    warp, _ = import_warp()
    if device != "cpu" and not device.startswith("cuda"):
        raise ValueError(f"env.device must be 'cpu', 'cuda' or 'cuda:N', got {device!r}")
    if device.startswith("cuda") and not warp.is_cuda_available():
        raise ValueError(
            f"env.device: {device!r} asked for, but Warp finds no CUDA device on this "
            "machine; use env.device: cpu (slow, for tests) or run on a machine with a GPU"
        )
    return device


class WarpBatch:
    """``num_sims`` simulations of one model, advanced together on a MuJoCo Warp device.

    Args:
        model: the compiled model (its solver must not be PGS).
        num_sims: number of simulations (Warp worlds) N.
        exports: ``MjData`` slices to copy into :attr:`exported` after every step and reset,
            keyed by a name of the caller's choosing.
        rne_post_constraint: run ``rne_postconstraint`` after each step, as gymnasium does
            (needed for ``cfrc_ext``).
        device: Warp device, ``"cpu"`` or ``"cuda[:N]"``.
        num_threads: accepted for the same signature as :class:`MujocoBatch`; unused.

    Attributes:
        exported: (N, E) float64 host array; :meth:`view` returns the slice of one export.
        sensordata: (N, nsensordata) float64 host array of sensor values at the current states.
        torch_exported: (N, E) float32 tensor on the device, the same values.
        torch_sensordata: (N, nsensordata) float32 tensor on the device.

    Raises:
        ValueError: if ``num_sims`` is below 1, an export names an unknown field, or the
            model uses the PGS solver.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        num_sims: int,
        exports: dict[str, Export],
        *,
        rne_post_constraint: bool = False,
        device: str = "cpu",
        num_threads: int | None = None,
    ) -> None:
        if num_sims < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_sims}")
        if model.opt.solver == mujoco.mjtSolver.mjSOL_PGS:
            raise ValueError(
                "MuJoCo Warp has no PGS solver and this model asks for it; use the task's "
                "Newton-solver variant (e.g. Humanoid-v5-newton) with env.backend: warp"
            )
        self.warp, self.mjw = import_warp()
        # the whole integration state (time, qpos, qvel, act, warm start, ctrl, ...)
        self._state = int(self.mjw.State.INTEGRATION)
        self.model = model
        self.num_sims = num_sims
        self.num_threads = 1
        self.rne_post_constraint = rne_post_constraint
        self.device = warp_device(device)
        with self.warp.ScopedDevice(self.device):
            self.wmodel = self.mjw.put_model(model)
            self.wdata = self.mjw.make_data(model, nworld=num_sims)
            size = mujoco.mj_stateSize(model, self._state)
            self._saved = self.warp.zeros((num_sims, size), dtype=float)
            self._keep = self.warp.zeros(num_sims, dtype=bool)
            self._reset_mask = self.warp.zeros(num_sims, dtype=bool)
        self._torch_device = torch.device("cpu" if self.device == "cpu" else self.device)

        self._fields = export_bounds(mujoco.MjData(model), exports)
        self._slices = export_slices(self._fields, list(exports))
        for field, _, _ in self._fields:
            if not hasattr(self.wdata, field):
                raise ValueError(f"export of {field!r}: MuJoCo Warp's Data has no such field")
        width = sum(stop - start for _, start, stop in self._fields)
        self.torch_exported = torch.zeros((num_sims, width), device=self._torch_device)
        self.torch_sensordata = torch.zeros(
            (num_sims, model.nsensordata), device=self._torch_device
        )
        self.exported = np.zeros((num_sims, width))
        self.sensordata = np.zeros((num_sims, model.nsensordata))
        self._ctrl = self._tensor("ctrl")
        self._qpos = self._tensor("qpos")
        self._qvel = self._tensor("qvel")

    def _tensor(self, field: str) -> torch.Tensor:
        """(N, size) zero-copy torch view of a Warp ``Data`` field."""
        tensor = self.warp.to_torch(getattr(self.wdata, field))
        return tensor.reshape(self.num_sims, -1)

    def view(self, name: str) -> np.ndarray:
        """The (N, length) columns of :attr:`exported` that hold export ``name``."""
        return self.exported[:, self._slices[name]]

    def step(self, ctrl: np.ndarray, nstep: int, active: np.ndarray | None = None) -> None:
        """Set controls and advance the active simulations by ``nstep`` substeps.

        Args:
            ctrl: (N, nu) controls.
            nstep: number of ``step`` calls (the task's frame skip).
            active: (N,) bool mask of simulations to step; ``None`` for all.
        """
        mjw, warp = self.mjw, self.warp
        keep = None if active is None or np.all(active) else ~np.asarray(active, dtype=bool)
        with warp.ScopedDevice(self.device):
            if keep is not None:  # remember the worlds that sit out, to restore them after
                warp.to_torch(self._keep).copy_(torch.from_numpy(keep))
                mjw.get_state(self.wmodel, self.wdata, self._saved, self._state)
            self._ctrl.copy_(torch.as_tensor(ctrl, dtype=torch.float32))
            for _ in range(nstep):
                mjw.step(self.wmodel, self.wdata)
            if self.rne_post_constraint:
                mjw.rne_postconstraint(self.wmodel, self.wdata)
            if keep is not None:
                mjw.set_state(self.wmodel, self.wdata, self._saved, self._state, self._keep)
            rows = None if keep is None else torch.from_numpy(np.flatnonzero(~keep))
            rows = None if rows is None else rows.to(self._torch_device)
            # exports read the post-step data (cfrc_ext, ...) before collision overwrites it
            parts = [self._tensor(f)[:, a:b].clone() for f, a, b in self._fields]
            if self.model.nsensordata:
                mjw.kinematics(self.wmodel, self.wdata)
                mjw.collision(self.wmodel, self.wdata)
                mjw.sensor_pos(self.wmodel, self.wdata)
            self._store(torch.cat(parts, dim=1), self._tensor("sensordata"), rows)

    def _store(self, exported: torch.Tensor, sensors: torch.Tensor, rows: torch.Tensor | None):
        """Write the rows of fresh exports and sensors into the device and host arrays."""
        if rows is None:
            self.torch_exported.copy_(exported)
            self.torch_sensordata.copy_(sensors)
            self.exported[:] = exported.cpu().double().numpy()
            self.sensordata[:] = sensors.cpu().double().numpy()
            return
        self.torch_exported[rows] = exported[rows]
        self.torch_sensordata[rows] = sensors[rows]
        host = rows.cpu().numpy()
        self.exported[host] = exported[rows].cpu().double().numpy()
        self.sensordata[host] = sensors[rows].cpu().double().numpy()

    def reset(self, ids: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> None:
        """Reset simulations ``ids`` to the given states, as gymnasium's ``set_state``.

        Args:
            ids: (n,) indices of the simulations to reset.
            qpos: (n, nq) positions.
            qvel: (n, nv) velocities.
        """
        ids = np.asarray(ids, dtype=np.int64)
        if ids.size == 0:
            return
        mjw, warp = self.mjw, self.warp
        mask = np.zeros(self.num_sims, dtype=bool)
        mask[ids] = True
        rows = torch.from_numpy(ids).to(self._torch_device)
        with warp.ScopedDevice(self.device):
            warp.to_torch(self._reset_mask).copy_(torch.from_numpy(mask))
            mjw.reset_data(self.wmodel, self.wdata, reset=self._reset_mask)
            # MuJoCo's mj_resetData zeros what only rnePostConstraint computes (forward does
            # not), so gymnasium's first observation holds cfrc_ext = 0; Warp's reset keeps it
            for field in ("cacc", "cfrc_int", "cfrc_ext"):
                self._tensor(field)[rows] = 0.0
            self._qpos[rows] = torch.as_tensor(qpos, dtype=torch.float32).to(self._torch_device)
            self._qvel[rows] = torch.as_tensor(qvel, dtype=torch.float32).to(self._torch_device)
            # forward recomputes every world's derived quantities from its own state; the
            # next step recomputes them anyway, so the other worlds' trajectories are intact
            mjw.forward(self.wmodel, self.wdata)
            parts = [self._tensor(f)[:, a:b] for f, a, b in self._fields]
            self._store(torch.cat(parts, dim=1), self._tensor("sensordata"), rows)
