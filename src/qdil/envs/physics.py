"""Many MuJoCo simulations of one model, stepped in one call on all cores.

The hot path of every qdil run is physics. :class:`MujocoBatch` keeps one ``MjData`` per
simulation and advances all of them in a single numba kernel that calls MuJoCo's C API
directly (``mj_step``, ``mj_rnePostConstraint``, ...) with the GIL released and the
simulations spread over ``num_threads`` threads. No Python runs per simulation.

Why not ``mujoco.rollout`` or ``mujoco.batch``: ``rollout`` zeroes the solver warm start on
every call, so its trajectories drift away from ``mj_step``'s (gymnasium's); ``batch`` keeps
the warm start but cannot run ``mj_rnePostConstraint`` after a step, which gymnasium's
Humanoid and Ant observations need (``cfrc_ext``). The kernel here does exactly what
gymnasium's ``MujocoEnv.do_simulation`` does, so trajectories are bit-identical.

Foot contacts are evaluated *at the new state*, which ``mj_step`` alone does not do (its
contact list belongs to the state before its last integration). The kernel ends every env
step with ``mj_step1`` at the new state: MuJoCo's position and velocity stages, the
collision detection among them, and the position-stage ``contact`` sensors (added to the
model by the caller) that report whether each foot touches the floor. The next env step's
first substep then does only what ``mj_step`` does after those stages (``mj_forwardSkip``
from the velocity stage, ``mj_checkAcc``, the model's integrator: RK4, Euler or implicit),
so the contact pass costs nothing extra and every substep computes exactly what
``mj_step`` would (``mj_step1`` + ``mj_step2`` is MuJoCo's own split of ``mj_step``; the
split here keeps RK4, which ``mj_step2`` would replace by Euler). Everything the task reads
from the post-step data (positions, ``cinert``, ``cfrc_ext``, ...) is copied out *before*
``mj_step1`` overwrites the derived quantities. Every simulation is therefore kept in that
"position and velocity stages done" condition: after construction (``mj_forward``), after
a reset (``mj_forward``, as gymnasium's ``set_state``) and after every step. One visible
difference remains, for a diverged simulation only: MuJoCo's ``mj_checkPos``/``mj_checkVel``
(NaN or huge values reset the data with a warning) now run at the end of the step that
diverged instead of at the start of the next, so that step's foot flags describe the reset
state; its exported observation is the diverged one, as before.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import mujoco
import numba
import numpy as np
import torch
from numba import prange
from typing_extensions import override

from qdil.envs.mujoco_c import MUJOCO_C, cached_njit, call_pp, call_ppi, call_ppii
from qdil.envs.physics_base import Export, PhysicsBatch, reset_ids
from qdil.timing import PHYSICS, timed

# The kernels call MuJoCo through the addresses in ``c`` (qdil.envs.mujoco_c.MUJOCO_C), not
# through ctypes globals, so that numba caches them on disk. numba rebuilds a cached kernel
# when this file changes, not when mujoco_c.py does: edit both, or clear the cache.


@cached_njit(nogil=True)
def _copy_out(c, i, sources, lengths, offsets, out):  # pragma: no cover - numba
    base = out.ctypes.data + i * out.shape[1] * 8
    for f in range(sources.shape[0]):
        call_ppi(c.mju_copy, base + offsets[f] * 8, sources[f, i], lengths[f])


@cached_njit(nogil=True)
def _reset_one(c, model, data, qpos_ptr, qvel_ptr, qpos, qvel, j):  # pragma: no cover - numba
    """Exactly gymnasium's MujocoEnv.reset + set_state: reset, write row j's state, forward."""
    nq = qpos.shape[1]
    nv = qvel.shape[1]
    call_pp(c.mj_reset_data, model, data)
    call_ppi(c.mju_copy, qpos_ptr, qpos.ctypes.data + j * nq * 8, nq)
    call_ppi(c.mju_copy, qvel_ptr, qvel.ctypes.data + j * nv * 8, nv)
    call_pp(c.mj_forward, model, data)


# MuJoCo's mjtStage and mjtIntegrator values, as plain ints for the kernel
_STAGE_VEL = int(mujoco.mjtStage.mjSTAGE_VEL)
_RK4 = int(mujoco.mjtIntegrator.mjINT_RK4)
_IMPLICIT = int(mujoco.mjtIntegrator.mjINT_IMPLICIT)
_IMPLICITFAST = int(mujoco.mjtIntegrator.mjINT_IMPLICITFAST)


@cached_njit(nogil=True)
def _first_substep(c, model, data, integrator):  # pragma: no cover - numba
    """``mj_step`` on data whose position and velocity stages ran at the current state.

    What ``mj_step`` does after ``mj_checkPos``, ``mj_checkVel`` and those two stages (which
    ``mj_step1`` at the end of the previous step, or a reset's ``mj_forward``, did): the
    acceleration stage with the new controls, ``mj_checkAcc`` and the integrator.
    """
    call_ppii(c.mj_forward_skip, model, data, _STAGE_VEL, 0)
    call_pp(c.mj_check_acc, model, data)
    if integrator == _RK4:
        call_ppi(c.mj_runge_kutta, model, data, 4)
    elif integrator in (_IMPLICIT, _IMPLICITFAST):
        call_pp(c.mj_implicit, model, data)
    else:
        call_pp(c.mj_euler, model, data)


@cached_njit(nogil=True, parallel=True)
def _step_kernel(
    c,
    model,
    datas,
    ctrl_ptrs,
    ctrl,
    active,
    nstep,
    integrator,
    rne,
    sources,
    lengths,
    offsets,
    out,
    sensor_ptrs,
    sensors,
    reset_rows,
    qpos_ptrs,
    qvel_ptrs,
    qpos,
    qvel,
):  # pragma: no cover - numba
    nu = ctrl.shape[1]
    nsensor = sensors.shape[1]
    for i in prange(datas.shape[0]):
        if reset_rows[i] >= 0:  # a reset in the same parallel region saves a second launch
            _reset_one(c, model, datas[i], qpos_ptrs[i], qvel_ptrs[i], qpos, qvel, reset_rows[i])
            _copy_out(c, i, sources, lengths, offsets, out)
            if nsensor > 0:
                call_ppi(c.mju_copy, sensors.ctypes.data + i * nsensor * 8, sensor_ptrs[i], nsensor)
            continue
        if not active[i] or nstep < 1:
            continue
        data = datas[i]
        call_ppi(c.mju_copy, ctrl_ptrs[i], ctrl.ctypes.data + i * nu * 8, nu)
        _first_substep(c, model, data, integrator)
        for _ in range(nstep - 1):
            call_pp(c.mj_step, model, data)
        if rne:
            call_pp(c.mj_rne_post_constraint, model, data)
        _copy_out(c, i, sources, lengths, offsets, out)
        # the next step's position and velocity stages, and the contact sensors at this state
        call_pp(c.mj_step1, model, data)
        if nsensor > 0:
            call_ppi(c.mju_copy, sensors.ctypes.data + i * nsensor * 8, sensor_ptrs[i], nsensor)


# chunks of simulations per physics thread in a step (docs/benchmarks.md, "Environments")
CHUNKS_PER_THREAD = 8


def default_num_threads() -> int:
    """Threads for physics: ``$QDIL_NUM_THREADS`` if set, else every core this process may use."""
    configured = os.environ.get("QDIL_NUM_THREADS")
    if configured:
        return max(1, min(int(configured), numba.config.NUMBA_NUM_THREADS))
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # macOS and Windows have no affinity API
        cores = os.cpu_count() or 1
    return max(1, min(cores, numba.config.NUMBA_NUM_THREADS))


class MujocoBatch(PhysicsBatch):
    """``num_sims`` simulations of one model, advanced together on ``num_threads`` threads.

    Args:
        model: the compiled model; shared read-only by all simulations.
        num_sims: number of simulations N.
        exports: ``MjData`` slices to copy into ``exported`` after every step and reset,
            keyed by a name of the caller's choosing (:class:`PhysicsBatch`).
        rne_post_constraint: run ``mj_rnePostConstraint`` after each step, as gymnasium does
            (needed for ``cfrc_ext``).
        num_threads: physics threads; ``None`` for every available core.

    Raises:
        ValueError: if ``num_sims`` or ``num_threads`` is out of range or an export names an
            unknown field.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        num_sims: int,
        exports: dict[str, Export],
        *,
        rne_post_constraint: bool = False,
        num_threads: int | None = None,
    ) -> None:
        super().__init__(model, num_sims, exports)
        max_threads = numba.config.NUMBA_NUM_THREADS
        if num_threads is not None and not 1 <= num_threads <= max_threads:
            raise ValueError(
                f"num_threads must be between 1 and {max_threads} (NUMBA_NUM_THREADS), "
                f"got {num_threads}"
            )
        self.num_threads = num_threads or default_num_threads()
        # prange hands out chunks of this many simulations as threads free up (numba splits
        # into one static block per thread otherwise), about CHUNKS_PER_THREAD per thread: a
        # step waits less for a thread whose simulations hit more contacts or whose core
        # another process holds; results do not depend on it (each simulation is independent)
        self.chunk_size = max(1, -(-num_sims // (CHUNKS_PER_THREAD * self.num_threads)))
        self.rne_post_constraint = rne_post_constraint
        if model.opt.enableflags & mujoco.mjtEnableBit.mjENBL_FWDINV:
            raise ValueError(
                "the model enables fwdinv (option/flag fwdinv); qdil's physics kernel does not "
                "compare forward and inverse dynamics; disable it in the model"
            )
        self._integrator = int(model.opt.integrator)
        self.datas = [mujoco.MjData(model) for _ in range(num_sims)]
        for data in self.datas:  # the stages a step's first substep expects done (see above)
            mujoco.mj_forward(model, data)
        self._model_ptr = model._address
        self._data_ptrs = np.array([d._address for d in self.datas], dtype=np.int64)
        self._ctrl_ptrs = self._pointers("ctrl")
        self._qpos_ptrs = self._pointers("qpos")
        self._qvel_ptrs = self._pointers("qvel")
        self._sensor_ptrs = self._pointers("sensordata")

        sources = [self._pointers(field) + 8 * start for field, start, _ in self._bounds]
        lengths = [stop - start for _, start, stop in self._bounds]
        offsets = [columns.start for columns in self._slices.values()]
        self._sources = np.array(sources, dtype=np.int64).reshape(len(sources), num_sims)
        self._lengths = np.array(lengths, dtype=np.int32)
        self._offsets = np.array(offsets, dtype=np.int32)
        self._all = np.ones(num_sims, dtype=np.bool_)
        self._none = np.zeros(num_sims, dtype=np.bool_)
        self._idle_ctrl = np.zeros((num_sims, model.nu))
        self._no_reset = (
            np.full(num_sims, -1, dtype=np.int64),
            np.zeros((0, model.nq)),
            np.zeros((0, model.nv)),
        )

    def _pointers(self, field: str) -> np.ndarray:
        return np.array([getattr(d, field).ctypes.data for d in self.datas], dtype=np.int64)

    @override
    @timed(PHYSICS)
    def step(
        self,
        ctrl: np.ndarray,
        nstep: int,
        active: np.ndarray | None = None,
        reset: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> None:
        # the resets and the steps run in one parallel region (one kernel call)
        rows, qpos, qvel = self._no_reset
        ids = reset_ids(reset, active)
        if ids is not None:
            _, qpos, qvel = reset
            rows = np.full(self.num_sims, -1, dtype=np.int64)
            rows[ids] = np.arange(ids.size)
            qpos = np.ascontiguousarray(qpos, dtype=np.float64)
            qvel = np.ascontiguousarray(qvel, dtype=np.float64)
        # numba's OpenMP pool, launched at its first use (here), sets the calling thread's
        # OpenMP thread count, which torch shares, to NUMBA_NUM_THREADS (every core):
        # torch, asked for one thread, then ran on all of them, and each small elementwise
        # op (tanh, exp, sqrt) paid a parallel region and a spinning worker, about 3 ms of
        # CPU per op on a loaded 2-core machine. Keep torch's count: torch computes on the
        # threads it was given, as in the tests (tests/conftest.py sets one after the pool).
        torch_threads = torch.get_num_threads()
        numba.set_num_threads(self.num_threads)
        with numba.parallel_chunksize(self.chunk_size):
            _step_kernel(
                MUJOCO_C,
                self._model_ptr,
                self._data_ptrs,
                self._ctrl_ptrs,
                ctrl,
                self._all if active is None else active,
                nstep,
                self._integrator,
                self.rne_post_constraint,
                self._sources,
                self._lengths,
                self._offsets,
                self.exported,
                self._sensor_ptrs,
                self.sensordata,
                rows,
                self._qpos_ptrs,
                self._qvel_ptrs,
                qpos,
                qvel,
            )
        if torch.get_num_threads() != torch_threads:
            torch.set_num_threads(torch_threads)

    @override
    @timed(PHYSICS)
    def reset(self, ids: np.ndarray, qpos: np.ndarray, qvel: np.ndarray) -> None:
        # the step kernel with no simulation stepping: one kernel serves both
        self.step(self._idle_ctrl, 0, self._none, reset=(ids, qpos, qvel))


def add_contact_sensors(spec: mujoco.MjSpec, geoms: Sequence[str], floor: str) -> None:
    """Add one ``contact`` sensor per foot geom, reporting whether it touches ``floor``.

    The sensor's ``found`` value counts the contacts between the two geoms in MuJoCo's
    contact list (``data.contact``, within the geoms' margin). It is a position-stage sensor,
    so it only needs kinematics and collision detection.

    Args:
        spec: the model spec to edit in place.
        geoms: foot geom names, in measure order.
        floor: the floor geom name.

    Raises:
        ValueError: if a geom does not exist in the model.
    """
    names = {g.name for g in spec.geoms}
    for name in (*geoms, floor):
        if name not in names:
            raise ValueError(f"geom {name!r} not in the model; geoms are {sorted(names)}")
    for name in geoms:
        sensor = spec.add_sensor()
        sensor.name = f"qdil_contact_{name}"
        sensor.type = mujoco.mjtSensor.mjSENS_CONTACT
        sensor.objtype = mujoco.mjtObj.mjOBJ_GEOM
        sensor.objname = name
        sensor.reftype = mujoco.mjtObj.mjOBJ_GEOM
        sensor.refname = floor
        sensor.intprm[0] = 1  # data="found"
        sensor.intprm[2] = 1  # num: one slot suffices for a found flag
