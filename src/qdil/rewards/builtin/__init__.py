"""Built-in reward models; importing this package registers them."""

from qdil.rewards.builtin.true_reward import TrueReward

__all__ = ["TrueReward"]
