"""Reward models: the ``RewardModel`` contract, the registry and the built-in models.

The names below load on first use (PEP 562), so that a submodule that needs no model,
:mod:`qdil.rewards.names`, imports neither Lightning nor torch.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from qdil.rewards.base import NonFiniteRewardError, RewardModel
    from qdil.rewards.registry import discover, get_reward, list_rewards, register_reward

_HOMES = {
    "NonFiniteRewardError": "qdil.rewards.base",
    "RewardModel": "qdil.rewards.base",
    "discover": "qdil.rewards.registry",
    "get_reward": "qdil.rewards.registry",
    "list_rewards": "qdil.rewards.registry",
    "register_reward": "qdil.rewards.registry",
}

__all__ = [
    "NonFiniteRewardError",
    "RewardModel",
    "discover",
    "get_reward",
    "list_rewards",
    "register_reward",
]


def __getattr__(name: str) -> Any:
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_HOMES[name]), name)
    globals()[name] = value  # looked up once
    return value
