"""Writing a :class:`~qdil.export.policy.GaitPolicy` as ONNX or as a ``torch.export`` program.

Both take a batch of observations of any size, ``(B, obs_dim)`` float32, and give
``(B, A)`` float32 actions: input ``obs``, output ``action``.
"""

from __future__ import annotations

import logging
import warnings
from pathlib import Path

import torch
from torch.export import Dim

from qdil.export.policy import GaitPolicy

SUFFIXES = {"onnx": ".onnx", "torch": ".pt2"}
"""File suffix of each policy format."""

ONNX_OPSET = 18


def _program(policy: GaitPolicy, obs_dim: int) -> torch.export.ExportedProgram:
    example = (torch.zeros(2, obs_dim),)
    batch = {"obs": {0: Dim("batch", min=1)}}
    return torch.export.export(policy, example, dynamic_shapes=batch, strict=False)


def save_policy(policy: GaitPolicy, obs_dim: int, fmt: str, path: Path) -> Path:
    """Write ``policy`` to ``path`` in ``fmt`` (``onnx`` or ``torch``); returns the path.

    Raises:
        ValueError: for an unknown format.
        ImportError: for ONNX without its exporter (``pip install -e ".[export]"``).
    """
    if fmt not in SUFFIXES:
        raise ValueError(f"--format must be onnx, torch or minari, got {fmt!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "torch":
        torch.export.save(_program(policy, obs_dim), path)
        return path
    try:
        import onnxscript  # noqa: F401 - torch's ONNX exporter needs it
    except ImportError as error:
        raise ImportError(
            f"--format onnx needs the ONNX exporter ({error}); install it with "
            '`pip install -e ".[export]"` (onnx, onnxscript, onnxruntime)'
        ) from None
    exporter_log = logging.getLogger("torch.onnx")
    level = exporter_log.level
    exporter_log.setLevel(logging.ERROR)  # "torchvision is not installed", and the like
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            program = torch.onnx.export(
                _program(policy, obs_dim),
                input_names=["obs"],
                output_names=["action"],
                opset_version=ONNX_OPSET,
                dynamo=True,
                verbose=False,
            )
    finally:
        exporter_log.setLevel(level)
    program.save(str(path))
    return path
