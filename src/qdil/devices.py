"""The run's torch device: where its physics steps, so where its torch work runs.

One setting, ``env.device``, places a run: the physics (``env.backend: warp`` on ``cuda``),
the policies, VPPO's rollouts and updates, the reward model (Fabric's accelerator) and the
bonus. Only pyribs and xNES stay on the host, fed numpy arrays once per phase. The
environment's constructor checks ``env.backend`` and ``env.device`` here, once, before it
builds anything, and everything after it is handed the ``torch.device`` it got
(``LocomotionVectorEnv.device``); a setting that would split the run over two devices is
refused.
"""

from __future__ import annotations

import re

import torch

BACKENDS = ("mujoco", "warp")
"""Values of ``env.backend``: MuJoCo's C engine (CPU only) or MuJoCo Warp."""

DEVICE_BACKENDS = ("warp",)
"""Backends whose physics state lives in torch tensors on ``env.device`` (Warp's CPU device
included): RL steps them through :class:`~qdil.envs.torch_vector.TorchVectorEnv`, the
others through :class:`~qdil.envs.faces.HostFace`."""

_DEVICE = re.compile(r"cpu|cuda(:\d+)?")


def run_device(backend: str, device: str | torch.device) -> torch.device:
    """The torch device of a run with ``env.backend: backend`` and ``env.device: device``.

    Raises:
        ValueError: naming ``env.backend`` for an unknown backend, or ``env.device`` for a
            device that is malformed, absent from this machine or this torch build, or not
            where ``backend`` steps its physics (whether the installed Warp sees the GPU
            only Warp can say: :class:`~qdil.envs.warp_physics.WarpBatch` checks that).
    """
    if backend not in BACKENDS:
        raise ValueError(f"env.backend must be one of {list(BACKENDS)}, got {backend!r}")
    device = str(device)
    if not _DEVICE.fullmatch(device):
        raise ValueError(f"env.device must be 'cpu', 'cuda' or 'cuda:N', got {device!r}")
    if device == "cpu":
        return torch.device("cpu")
    if backend == "mujoco":
        raise ValueError(
            f"env.device: {device!r} with env.backend: mujoco would put the policies and "
            "reward models on the GPU and the physics on the CPU (MuJoCo's C engine), with "
            "host copies every step; set env.backend: warp to step the physics on the GPU "
            "too, or env.device: cpu"
        )
    if not torch.cuda.is_available():
        build = torch.version.cuda or "none (a CPU-only build)"
        raise ValueError(
            f"env.device: {device!r} asked for, but torch finds no CUDA device (torch "
            f"{torch.__version__}, CUDA {build}); install a CUDA build of torch on a machine "
            "with an NVIDIA GPU, or set env.device: cpu"
        )
    index = torch.device(device).index
    if index is not None and index >= torch.cuda.device_count():
        raise ValueError(
            f"env.device: {device!r}, but this machine has {torch.cuda.device_count()} CUDA "
            f"device(s), cuda:0 to cuda:{torch.cuda.device_count() - 1}"
        )
    return torch.device(device)


def fabric_settings(device: torch.device) -> dict[str, object]:
    """``lightning.Fabric`` keyword arguments that put the reward model on ``device``."""
    if device.type == "cpu":
        return {"accelerator": "cpu", "devices": 1}
    return {"accelerator": "cuda", "devices": [device.index or 0]}
