"""Reward models: the ``RewardModel`` contract, the registry and the built-in models."""

from qdil.rewards.base import NonFiniteRewardError, RewardModel
from qdil.rewards.registry import discover, get_reward, list_rewards, register_reward

__all__ = [
    "NonFiniteRewardError",
    "RewardModel",
    "discover",
    "get_reward",
    "list_rewards",
    "register_reward",
]
