"""The physics engines a locomotion task can run on, chosen by ``env.backend``.

``mujoco`` is MuJoCo's C engine stepped by numba kernels on the CPU
(:class:`~qdil.envs.physics.MujocoBatch`, the default, bit-identical to gymnasium);
``warp`` is MuJoCo Warp on a GPU or on Warp's CPU device
(:class:`~qdil.envs.warp_physics.WarpBatch`, float32, agrees within a tolerance). Both are
a :class:`~qdil.envs.physics_base.PhysicsBatch`.
"""

from __future__ import annotations

import mujoco
import torch

from qdil.devices import BACKENDS
from qdil.envs.physics import MujocoBatch
from qdil.envs.physics_base import Export, PhysicsBatch


def make_physics(
    backend: str,
    model: mujoco.MjModel,
    num_sims: int,
    exports: dict[str, Export],
    *,
    rne_post_constraint: bool,
    num_threads: int | None,
    device: torch.device,
    deterministic: bool = False,
) -> PhysicsBatch:
    """The batch of ``num_sims`` simulations of ``model`` on ``backend`` and ``device``.

    The pair was checked by :func:`qdil.devices.run_device` (the environment's constructor).
    ``deterministic`` asks MuJoCo Warp for its deterministic kernels; MuJoCo's C engine
    repeats its bits without asking.
    """
    if backend == "mujoco":  # the CPU
        return MujocoBatch(
            model,
            num_sims,
            exports,
            rne_post_constraint=rne_post_constraint,
            num_threads=num_threads,
        )
    if backend == "warp":
        from qdil.envs.warp_physics import WarpBatch  # optional dependency
        from qdil.envs.warp_startup import announce_warp_kernels, import_warp

        announce_warp_kernels(import_warp()[0])  # the first step may wait for a compile
        return WarpBatch(
            model,
            num_sims,
            exports,
            rne_post_constraint=rne_post_constraint,
            device=device,
            deterministic=deterministic,
        )
    raise ValueError(f"env.backend must be one of {list(BACKENDS)}, got {backend!r}")
