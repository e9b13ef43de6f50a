"""Method labels: the paper's name of what a run ran (reward model, bonus)."""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

DISPLAY_NAMES: dict[str, str] = {
    "true_reward": "PPGA-trueReward",
    "gail": "GAIL",
    "airl": "AIRL",
    "pwil": "PWIL",
    "maxentirl": "MaxEntIRL",
    "giril": "GIRIL",
    "wae_gail": "WAE-GAIL",
    "wae_wgail": "WAE-WGAIL",
    "mcwae_wgail": "mCWAE-WGAIL",
    "mcwae_gail": "mCWAE-GAIL",
    "vail": "VAIL",
    "diffail": "DiffAIL",
}
"""Registry names of reward models -> the names the paper's tables use."""


def reward_name(config: Mapping[str, Any]) -> str:
    """The reward model's registry name, or the last component of its class path.

    Args:
        config: a resolved recipe (``config.yaml``).
    """
    reward = config.get("reward")
    class_path = reward.get("class_path", "") if isinstance(reward, Mapping) else str(reward)
    if "." not in class_path:
        return class_path
    from qdil.rewards.names import declared_name

    declared = declared_name(class_path)  # read from the source: no Lightning to import
    if declared is not None:
        return declared
    from qdil.rewards import discover

    discover()
    module, _, qualname = class_path.rpartition(".")
    try:
        cls = getattr(importlib.import_module(module), qualname)
        return getattr(cls, "name", "") or qualname
    except Exception:  # a plugin that is not installed here: fall back to the class name
        return qualname


def method_label(config: Mapping[str, Any]) -> str:
    """The paper's name of a run's method: reward model plus ``-Bonus`` or ``-EBC``.

    Registry names map through :data:`DISPLAY_NAMES` (``mcwae_wgail`` -> ``mCWAE-WGAIL``);
    unknown names stay as they are.

    Args:
        config: a resolved recipe (``config.yaml``).
    """
    name = reward_name(config)
    label = DISPLAY_NAMES.get(name, DISPLAY_NAMES.get(name.lower(), name))
    bonus = config.get("bonus") or {}
    if isinstance(bonus, Mapping) and bonus.get("enabled"):
        label += "-EBC" if bonus.get("type") == "ebc" else "-Bonus"
    return label
