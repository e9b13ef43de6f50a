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
- it steps every world in each call. A world left out of ``step(active=...)`` is restored to
  its state from before the call, so it keeps its state as in :class:`MujocoBatch`.

Foot contacts are evaluated at the new state after each step exactly as the C engine does
it: kinematics, collision detection and the position-stage sensors (MuJoCo ``contact``
sensors added by :func:`~qdil.envs.physics.add_contact_sensors`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import Any

import mujoco
import numpy as np
import torch
from typing_extensions import override

from qdil.envs.physics_base import Export, PhysicsBatch, reset_ids


def import_warp() -> tuple[Any, Any]:
    """``(warp, mujoco_warp)``, or an ImportError that says how to install them."""
    from qdil.envs.warp_startup import cuda_driver_found, native_stderr_silenced

    try:
        import warp

        warp.config.quiet = True  # before mujoco_warp's import initialises Warp (banner)
        warp.config.log_level = warp.LOG_WARNING  # no line per kernel module loaded
        # without a CUDA driver Warp's C library prints a "Warp CUDA warning" whatever the
        # config; such a machine runs Warp on its CPU only, so the line is noise there
        with native_stderr_silenced(not cuda_driver_found()):
            warp.init()
        import mujoco_warp
    except ImportError as error:
        raise ImportError(
            "env.backend: warp needs MuJoCo Warp; install it with "
            '`pip install -e ".[warp]"` (mujoco-warp and warp-lang)'
        ) from error
    return warp, mujoco_warp


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

    Attributes:
        torch_exported: (N, E) float32 tensor on the device, the same values.
        torch_sensordata: (N, nsensordata) float32 tensor on the device.
        torch_device: ``device``.

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
        with self.warp.ScopedDevice(self.warp_device):
            self.wmodel = self.mjw.put_model(model)
            self.wdata = self.mjw.make_data(model, nworld=num_sims)
            size = mujoco.mj_stateSize(model, self._state)
            self._saved = self.warp.zeros((num_sims, size), dtype=float)
            self._keep = self.warp.zeros(num_sims, dtype=bool)
            self._reset_mask = self.warp.zeros(num_sims, dtype=bool)
            # later launches go on torch's stream (_on_torch_stream): finish these first
            self.warp.synchronize_device(self.warp_device)
        self.torch_device = device
        self.graphs = graphs
        self._graphs: dict[tuple, Any] = {}  # None: launched from Python
        # a CUDA graph cannot be recorded on torch's legacy default stream: record on one
        # of Warp's and replay on torch's (the CPU device records without a stream)
        on_gpu = self.torch_device.type == "cuda"
        self._capture_stream = self.warp.Stream(self.warp_device) if on_gpu and graphs else None

        for field, _, _ in self._bounds:
            if not hasattr(self.wdata, field):
                raise ValueError(f"export of {field!r}: MuJoCo Warp's Data has no such field")
        self.torch_exported = torch.zeros(self.exported.shape, device=self.torch_device)
        self.torch_sensordata = torch.zeros(self.sensordata.shape, device=self.torch_device)
        self._ctrl = self._tensor("ctrl")
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
        stream = torch.cuda.current_stream(self.torch_device)
        return self.warp.ScopedStream(self.warp.stream_from_torch(stream))

    def _tensor(self, field: str) -> torch.Tensor:
        """(N, size) zero-copy torch view of a Warp ``Data`` field."""
        tensor = self.warp.to_torch(getattr(self.wdata, field))
        return tensor.reshape(self.num_sims, -1)

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
                restored after the call (every world is stepped: a mask saves no work).
        """
        mjw, warp = self.mjw, self.warp
        with self._on_torch_stream():
            if active is not None:  # remember the worlds that sit out, to restore them after
                warp.to_torch(self._keep).copy_(~active)
                mjw.get_state(self.wmodel, self.wdata, self._saved, self._state)
            self._ctrl.copy_(ctrl)
            self._launch(("step", nstep), lambda: self._substeps(nstep))
            if active is not None:
                mjw.set_state(self.wmodel, self.wdata, self._saved, self._state, self._keep)
            # exports read the post-step data (cfrc_ext, ...) before collision overwrites it
            exported = torch.cat([self._tensor(f)[:, a:b] for f, a, b in self._bounds], dim=1)
            if self.model.nsensordata:
                self._launch(("sensors",), self._sensor_pass)
            self._store_where(active, exported, self._tensor("sensordata"))

    def _substeps(self, nstep: int) -> None:
        """Launch ``nstep`` MuJoCo Warp steps (and ``rne_postconstraint`` if asked)."""
        for _ in range(nstep):
            self.mjw.step(self.wmodel, self.wdata)
        if self.rne_post_constraint:
            self.mjw.rne_postconstraint(self.wmodel, self.wdata)

    def _sensor_pass(self) -> None:
        """Launch the position stage that evaluates the contact sensors at the new state."""
        self.mjw.kinematics(self.wmodel, self.wdata)
        self.mjw.collision(self.wmodel, self.wdata)
        self.mjw.sensor_pos(self.wmodel, self.wdata)

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

    def _launch(self, key: tuple, launches: Callable[[], None]) -> None:
        """Run ``launches`` (Warp launches on fixed arrays only), from a graph after the first.

        The first call launches them one by one (Warp compiles and loads their modules) and
        records them in a graph without running them again; later calls replay the graph on
        the current stream (torch's, see :meth:`_on_torch_stream`). Python's cost of a
        MuJoCo Warp step is hundreds of launches; a replay is one.
        """
        graph = self._graphs.get(key)
        if graph is not None:
            self.warp.capture_launch(graph)
            return
        launches()
        if not self.graphs or key in self._graphs:  # a None entry: it could not be recorded
            return
        try:
            with self._recording_stream():
                capture = self.warp.ScopedCapture(device=self.warp_device)
                with capture:
                    launches()
            self._graphs[key] = capture.graph
        except RuntimeError:  # a launch that cannot be recorded: launch it from Python
            self._graphs[key] = None

    def _recording_stream(self) -> Any:
        """A context whose Warp launches go to the stream graphs are recorded on.

        On a GPU that is a stream of Warp's own that first waits for torch's; the CPU
        device records without a stream.
        """
        if self._capture_stream is None:
            return contextlib.nullcontext()
        return self.warp.ScopedStream(self._capture_stream)

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
        mjw, warp = self.mjw, self.warp
        column = mask[:, None]
        with self._on_torch_stream():
            warp.to_torch(self._reset_mask).copy_(mask)
            self._launch(
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
            self._launch(("observed",), self._observed_stages)
            exported = torch.cat([self._tensor(f)[:, a:b] for f, a, b in self._bounds], dim=1)
            self._store_where(mask, exported, self._tensor("sensordata"))
