"""Many MuJoCo simulations of one model on MuJoCo Warp (GPU, or Warp's CPU device).

:class:`WarpBatch` is the MuJoCo Warp twin of :class:`~qdil.envs.physics.MujocoBatch`: the
same constructor, :attr:`exported` and :attr:`sensordata` arrays, :meth:`view`,
:meth:`step` and :meth:`reset`, so that :class:`~qdil.envs.vector.LocomotionVectorEnv` and
everything above it run unchanged on either engine (``env.backend: warp``). All worlds live in
one ``mujoco_warp.Data`` on the Warp device; :attr:`torch_exported` and
:attr:`torch_sensordata` are their torch tensors on that device. :meth:`step` and
:meth:`reset` (gymnasium's numpy face) copy them to the host after every call;
:meth:`step_torch` and :meth:`reset_where` (the torch face,
:class:`~qdil.envs.torch_vector.TorchVectorEnv`) take torch tensors and neither copy nor
wait for the device.

What differs from the C engine, and why the results agree only within a tolerance
(``tests/envs/test_warp_backend.py`` states it):

- MuJoCo Warp computes in float32 (the C engine in float64);
- it has no PGS solver: a model that asks for PGS (gymnasium's Humanoid) must be switched to
  Newton by the caller, which changes its dynamics (the ``Humanoid-v5-newton`` task);
- it steps every world of a ``Data`` in each call. A world left out of ``step(active=...)``
  is restored to its state from before the call, so it keeps its state as in
  :class:`MujocoBatch`; :meth:`WarpBatch.narrow` moves the worlds that will still be
  stepped into a smaller ``Data``, so that the others stop costing physics.

Foot contacts are evaluated at the new state after each step exactly as the C engine does
it: kinematics, collision detection and the position-stage sensors (MuJoCo ``contact``
sensors added by :func:`~qdil.envs.physics.add_contact_sensors`).
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
import torch
from typing_extensions import override

from qdil.envs.physics_base import Export, PhysicsBatch, reset_ids
from qdil.envs.warp_graphs import WarpGraphs
from qdil.envs.warp_startup import import_warp
from qdil.envs.warp_worlds import Worlds, copy_states


class WarpBatch(PhysicsBatch):
    """``num_sims`` simulations of one model, advanced together on a MuJoCo Warp device.

    Args:
        model: the compiled model (its solver must not be PGS).
        num_sims: number of simulations (Warp worlds) N.
        exports: ``MjData`` slices to copy into ``exported`` after every step and reset,
            keyed by a name of the caller's choosing (:class:`PhysicsBatch`).
        rne_post_constraint: run ``rne_postconstraint`` after each step, as gymnasium does
            (needed for ``cfrc_ext``).
        device: the torch device of the Warp device, CPU or CUDA (checked by
            :func:`qdil.devices.run_device`).
        num_threads: accepted for the same signature as :class:`MujocoBatch`; unused.
        graphs: record each fixed sequence of Warp launches (a frame skip of steps, the
            sensor pass, a reset) in a Warp graph at its first call and replay it after:
            one launch instead of hundreds from Python, the same kernels on the same arrays
            (results are bit-identical; ``tests/envs/test_warp_backend.py``).
        deterministic: MuJoCo Warp's deterministic kernels (``Option.deterministic``: sorted
            contacts, ordered constraint rows and reductions), so that the same steps give
            the same bits on CUDA too, at a cost (docs/guides/gpu.md); Warp's CPU device
            repeats without them.

    Attributes:
        torch_exported: (N, E) float32 tensor on the device, the same values.
        torch_sensordata: (N, nsensordata) float32 tensor on the device.
        torch_device: ``device``.
        world_steps: env steps simulated so far, summed over the worlds each one advanced
            (narrowed worlds count once each; the cost of physics on a device).
        graphs: the :class:`~qdil.envs.warp_graphs.WarpGraphs` of the launch sequences.

    ``exported`` and ``sensordata`` are host copies of :attr:`torch_exported` and
    :attr:`torch_sensordata`, made by :meth:`step` and :meth:`reset`.

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
        device: torch.device = torch.device("cpu"),  # noqa: B008 - an immutable value
        num_threads: int | None = None,
        graphs: bool = True,
        deterministic: bool = False,
    ) -> None:
        super().__init__(model, num_sims, exports)
        if model.opt.solver == mujoco.mjtSolver.mjSOL_PGS:
            raise ValueError(
                "MuJoCo Warp has no PGS solver and this model asks for it; use the task's "
                "Newton-solver variant (e.g. Humanoid-v5-newton) with env.backend: warp"
            )
        self.warp, self.mjw = import_warp()
        if device.type == "cuda" and not self.warp.is_cuda_available():
            raise ValueError(
                f"env.device: {str(device)!r} asked for, but Warp finds no CUDA device on this "
                "machine; use env.device: cpu (slow, for tests) or run on a machine with a GPU"
            )
        # the whole integration state (time, qpos, qvel, act, warm start, ctrl, ...)
        self._state = int(self.mjw.State.INTEGRATION)
        self.num_threads = 1
        self.rne_post_constraint = rne_post_constraint
        self.warp_device = str(device)  # Warp's name of it: "cpu", "cuda" or "cuda:N"
        self.torch_device = device
        with self.warp.ScopedDevice(self.warp_device):
            self.wmodel = self.mjw.put_model(model)
            self.wmodel.opt.deterministic = deterministic  # True: every DeterminismType flag
            self._all = Worlds.make(self.warp, self.mjw, model, num_sims, self._state)
            self._reset_mask = self.warp.zeros(num_sims, dtype=bool)
            # later launches go on torch's stream (_on_torch_stream): finish these first
            self.warp.synchronize_device(self.warp_device)
        self.wdata = self._all.data
        self._worlds = self._all  # the worlds stepped: all, or a narrowed batch of them
        self._rows: torch.Tensor | None = None  # narrowed: (size,) world of each of _worlds
        self._held = num_sims  # worlds held by _worlds; narrowed, the rest pad its batch
        self._narrowed: dict[int, Worlds] = {}  # smaller batches by size, made when first used
        self.world_steps = 0
        self.graphs = WarpGraphs(self.warp, self.warp_device, graphs)

        for field, _, _ in self._bounds:
            if not hasattr(self.wdata, field):
                raise ValueError(f"export of {field!r}: MuJoCo Warp's Data has no such field")
        self.torch_exported = torch.zeros(self.exported.shape, device=self.torch_device)
        self.torch_sensordata = torch.zeros(self.sensordata.shape, device=self.torch_device)
        self._qpos = self._tensor("qpos")
        self._qvel = self._tensor("qvel")

    def _on_torch_stream(self) -> Any:
        """A context in which Warp launches on torch's current stream of the device.

        Warp and torch share the data zero-copy; on one CUDA stream their kernels run in
        the order they are launched, so neither reads what the other has not written yet,
        and no one waits on the host. On the CPU every launch finishes before it returns.
        """
        if self.torch_device.type != "cuda":
            return self.warp.ScopedDevice(self.warp_device)
        if self.graphs.outer_stream is not None:  # recording: torch's capture is already ordered
            return self.warp.ScopedStream(self.graphs.outer_stream, sync_enter=False)
        stream = torch.cuda.current_stream(self.torch_device)
        return self.warp.ScopedStream(self.warp.stream_from_torch(stream))

    def _tensor(self, field: str) -> torch.Tensor:
        """(N, size) zero-copy torch view of a Warp ``Data`` field of all worlds."""
        return self._all.field(self.warp, field)

    @override
    def step(
        self,
        ctrl: np.ndarray,
        nstep: int,
        active: np.ndarray | None = None,
        reset: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> None:
        # every world is stepped: the inactive ones are restored after (step_torch)
        if reset_ids(reset, active) is not None:
            self.reset(*reset)
        keep = None if active is None or np.all(active) else ~np.asarray(active, dtype=bool)
        ctrl_t = torch.as_tensor(ctrl, dtype=torch.float32).to(self.torch_device)
        mask = None if keep is None else torch.from_numpy(~keep).to(self.torch_device)
        self.step_torch(ctrl_t, nstep, mask)
        if keep is None:
            self.exported[:] = self.torch_exported.cpu().double().numpy()
            self.sensordata[:] = self.torch_sensordata.cpu().double().numpy()
        else:
            rows = np.flatnonzero(~keep)
            self._copy_rows_to_host(rows)

    def step_torch(
        self, ctrl: torch.Tensor, nstep: int, active: torch.Tensor | None = None
    ) -> None:
        """:meth:`step` on the device: torch inputs, no host copy and no host sync.

        Only :attr:`torch_exported` and :attr:`torch_sensordata` are updated (the host
        arrays are not).

        Args:
            ctrl: (N, nu) float32 controls on :attr:`torch_device`.
            nstep: number of ``step`` calls (the task's frame skip).
            active: (N,) bool tensor of simulations to step; ``None`` for all. The others are
                restored after the call (every world of the stepped ``Data`` is stepped: a
                mask saves no work, :meth:`narrow` does). After :meth:`narrow`, the worlds
                it left out are not stepped whatever ``active`` says.
        """
        mjw, warp, worlds, rows = self.mjw, self.warp, self._worlds, self._rows
        if rows is not None:  # the narrowed batch's own controls and mask
            ctrl = ctrl[rows]
            active = None if active is None else active[rows]
        self.world_steps += worlds.size
        with self._on_torch_stream():
            if active is not None:  # remember the worlds that sit out, to restore them after
                warp.to_torch(worlds.keep).copy_(~active)
                mjw.get_state(self.wmodel, worlds.data, worlds.saved, self._state)
            worlds.ctrl.copy_(ctrl)
            key = (worlds.size,)
            self.graphs.launch(("step", nstep, *key), lambda: self._substeps(nstep, worlds.data))
            if active is not None:
                mjw.set_state(self.wmodel, worlds.data, worlds.saved, self._state, worlds.keep)
            # exports read the post-step data (cfrc_ext, ...) before collision overwrites it
            exported = torch.cat([worlds.field(warp, f)[:, a:b] for f, a, b in self._bounds], dim=1)
            if self.model.nsensordata:
                self.graphs.launch(("sensors", *key), lambda: self._sensor_pass(worlds.data))
            sensors = worlds.field(warp, "sensordata")
            if rows is None:
                self._store_where(active, exported, sensors)
            else:  # the padding worlds' results are dropped
                held = slice(0, self._held)
                mask = None if active is None else active[held]
                self._scatter(rows[held], mask, exported[held], sensors[held])

    def _substeps(self, nstep: int, data: Any) -> None:
        """Launch ``nstep`` MuJoCo Warp steps (and ``rne_postconstraint`` if asked)."""
        for _ in range(nstep):
            self.mjw.step(self.wmodel, data)
        if self.rne_post_constraint:
            self.mjw.rne_postconstraint(self.wmodel, data)

    def _sensor_pass(self, data: Any) -> None:
        """Launch the position stage that evaluates the contact sensors at the new state."""
        self.mjw.kinematics(self.wmodel, data)
        self.mjw.collision(self.wmodel, data)
        self.mjw.sensor_pos(self.wmodel, data)

    def _scatter(
        self,
        rows: torch.Tensor,
        active: torch.Tensor | None,
        exported: torch.Tensor,
        sensors: torch.Tensor,
    ) -> None:
        """Write fresh exports and sensors of worlds ``rows`` (M,) where ``active`` (M,) holds."""
        if active is not None:
            exported = torch.where(active[:, None], exported, self.torch_exported[rows])
            sensors = torch.where(active[:, None], sensors, self.torch_sensordata[rows])
        self.torch_exported[rows] = exported
        self.torch_sensordata[rows] = sensors

    def narrow(self, rows: torch.Tensor | None) -> None:
        """Step only the worlds ``rows`` from now on, in a ``Data`` of fewer worlds.

        Their states move to a batch of the next power of two of worlds (padded with copies
        of the first, whose results are dropped), made at its first use and kept; the other
        worlds keep their states and stop costing physics until :meth:`widen` (which
        :meth:`reset_where` calls).
        A world computes the same bits in either batch (``tests/envs/test_warp_narrow.py``).
        Each call starts from all N worlds (the ones narrowed before are written back first).

        Args:
            rows: (M,) int64 tensor of distinct world indices on the device, or ``None`` to
                :meth:`widen` (as does an empty one: nothing is left to narrow to).
        """
        self.widen()
        if rows is None or not len(rows):
            return
        size = 1 << (len(rows) - 1).bit_length()
        if size >= self.num_sims:
            return
        target = self._narrowed.get(size)
        if target is None:
            with self.warp.ScopedDevice(self.warp_device):
                target = Worlds.make(self.warp, self.mjw, self.model, size, self._state)
                self.warp.synchronize_device(self.warp_device)
            self._narrowed[size] = target
        rows = rows.to(torch.int64)
        padded = torch.cat([rows, rows[:1].expand(size - len(rows))])
        with self._on_torch_stream():
            copy_states(*self._copy, (self._all, padded), (target, None))
        self._worlds, self._rows, self._held = target, padded, len(rows)

    def widen(self) -> None:
        """Write a narrowed batch's states back into their worlds, and step all N again."""
        if self._rows is None:
            return
        with self._on_torch_stream():
            held = slice(0, self._held)
            copy_states(*self._copy, (self._worlds, held), (self._all, self._rows[held]))
        self._worlds, self._rows, self._held = self._all, None, self.num_sims

    @property
    def _copy(self) -> tuple[Any, Any, Any, int]:
        """The first arguments of :func:`~qdil.envs.warp_worlds.copy_states`."""
        return self.warp, self.mjw, self.wmodel, self._state

    def _observed_stages(self) -> None:
        """Launch ``forward`` up to the actuator forces: all that exports and sensors read.

        ``forward`` goes on to the constraint solver, whose results (accelerations, constraint
        forces) no export reads and the next step computes afresh from the state; skipping it
        leaves every exported value and every later step bit-identical
        (``tests/envs/test_warp_backend.py``) at a fraction of the launches.
        """
        m, d, mjw = self.wmodel, self.wdata, self.mjw
        mjw.fwd_position(m, d, factorize=False)
        d.sensordata.zero_()
        mjw.sensor_pos(m, d)
        mjw.fwd_velocity(m, d)
        mjw.sensor_vel(m, d)
        mjw.fwd_actuation(m, d)

    def _store_where(
        self, rows: torch.Tensor | None, exported: torch.Tensor, sensors: torch.Tensor
    ) -> None:
        """Write fresh exports and sensors into the device arrays where ``rows`` (N,) holds."""
        if rows is None:
            self.torch_exported.copy_(exported)
            self.torch_sensordata.copy_(sensors)
            return
        self.torch_exported.copy_(torch.where(rows[:, None], exported, self.torch_exported))
        self.torch_sensordata.copy_(torch.where(rows[:, None], sensors, self.torch_sensordata))

    def _copy_rows_to_host(self, rows: np.ndarray) -> None:
        """Copy rows ``rows`` of the device arrays into the host arrays."""
        index = torch.from_numpy(rows).to(self.torch_device)
        self.exported[rows] = self.torch_exported[index].cpu().double().numpy()
        self.sensordata[rows] = self.torch_sensordata[index].cpu().double().numpy()

    @override
    def reset(self, ids: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> None:
        ids = np.asarray(ids, dtype=np.int64)
        if ids.size == 0:
            return
        mask = np.zeros(self.num_sims, dtype=bool)
        mask[ids] = True
        qpos_all = torch.zeros((self.num_sims, self.model.nq), dtype=torch.float64)
        qvel_all = torch.zeros((self.num_sims, self.model.nv), dtype=torch.float64)
        qpos_all[ids] = torch.as_tensor(qpos, dtype=torch.float64)
        qvel_all[ids] = torch.as_tensor(qvel, dtype=torch.float64)
        device = self.torch_device
        self.reset_where(
            torch.from_numpy(mask).to(device), qpos_all.to(device), qvel_all.to(device)
        )
        self._copy_rows_to_host(ids)

    def reset_where(self, mask: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        """Reset the simulations where ``mask`` holds, on the device and without a host sync.

        Args:
            mask: (N,) bool tensor of the simulations to reset.
            qpos: (N, nq) positions; only the masked rows are read.
            qvel: (N, nv) velocities; only the masked rows are read.
        """
        self.widen()
        mjw, warp = self.mjw, self.warp
        column = mask[:, None]
        with self._on_torch_stream():
            warp.to_torch(self._reset_mask).copy_(mask)
            self.graphs.launch(
                ("reset",), lambda: mjw.reset_data(self.wmodel, self.wdata, reset=self._reset_mask)
            )
            # MuJoCo's mj_resetData zeros what only rnePostConstraint computes (forward does
            # not), so gymnasium's first observation holds cfrc_ext = 0; Warp's reset keeps it
            for field in ("cacc", "cfrc_int", "cfrc_ext"):
                tensor = self._tensor(field)
                tensor.copy_(torch.where(column, 0.0, tensor))
            self._qpos.copy_(torch.where(column, qpos.to(torch.float32), self._qpos))
            self._qvel.copy_(torch.where(column, qvel.to(torch.float32), self._qvel))
            # the reset worlds' observed quantities; the other worlds' are recomputed from
            # their own states, and the next step recomputes everything anyway
            self.graphs.launch(("observed",), self._observed_stages)
            exported = torch.cat([self._tensor(f)[:, a:b] for f, a, b in self._bounds], dim=1)
            self._store_where(mask, exported, self._tensor("sensordata"))
