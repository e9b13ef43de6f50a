"""One namespace for the task formulas, on numpy arrays (host) or torch tensors (device).

The tasks compute observations, rewards and terminations with the few numpy functions
below. :func:`namespace` hands them ``numpy`` itself for numpy arrays, so gymnasium's numpy
face runs exactly the numpy code it always ran, and :data:`TORCH`, the same functions on
torch tensors, for the device face (:class:`~qdil.envs.torch_vector.TorchVectorEnv`),
whose arrays never leave the device.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import torch

# torch is imported inside the functions: they only run on tensors, when torch is loaded
# already, and `import qdil` (which registers the tasks) must not pay for torch.


class _TorchFunctions:
    """The numpy functions of the task formulas, with numpy's signatures, on torch tensors."""

    @staticmethod
    def concatenate(arrays: Sequence[torch.Tensor], axis: int = 0) -> torch.Tensor:
        import torch

        return torch.cat(list(arrays), dim=axis)

    @staticmethod
    def clip(x: torch.Tensor, low: float, high: float) -> torch.Tensor:
        import torch

        return torch.clip(x, low, high)

    @staticmethod
    def sum(x: torch.Tensor, axis: int | None = None) -> torch.Tensor:
        import torch

        return torch.sum(x) if axis is None else torch.sum(x, dim=axis)

    @staticmethod
    def square(x: torch.Tensor) -> torch.Tensor:
        import torch

        return torch.square(x)

    @staticmethod
    def isfinite(x: torch.Tensor) -> torch.Tensor:
        import torch

        return torch.isfinite(x)

    @staticmethod
    def all(x: torch.Tensor, axis: int) -> torch.Tensor:
        import torch

        return torch.all(x, dim=axis)

    @staticmethod
    def copy(x: torch.Tensor) -> torch.Tensor:

        return x.clone()

    @staticmethod
    def zeros_like(x: torch.Tensor, dtype: type = bool) -> torch.Tensor:
        import torch

        return torch.zeros_like(x, dtype=torch.bool if dtype is bool else x.dtype)


TORCH = _TorchFunctions()
"""numpy's functions of the task formulas, on torch tensors."""


def namespace(x: np.ndarray | torch.Tensor) -> Any:
    """``numpy`` for a numpy array, :data:`TORCH` for a torch tensor."""
    return np if isinstance(x, np.ndarray) else TORCH


def constant(
    value: np.ndarray, like: np.ndarray | torch.Tensor, cache: dict[Any, torch.Tensor]
) -> np.ndarray | torch.Tensor:
    """A task constant beside ``like``: ``value`` itself, or its tensor on ``like``'s device.

    The tensor is made once per device and dtype and kept in ``cache``, so a step on the
    device copies no constant from the host.
    """
    if isinstance(like, np.ndarray):
        return value
    key = (like.device, like.dtype)
    if key not in cache:
        import torch

        cache[key] = torch.as_tensor(value, dtype=like.dtype, device=like.device)
    return cache[key]
