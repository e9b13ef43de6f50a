"""Built-in reward models; importing this package registers them."""

from qdil.rewards.builtin.airl import AIRL
from qdil.rewards.builtin.gail import GAIL
from qdil.rewards.builtin.giril import GIRIL
from qdil.rewards.builtin.maxent_irl import MaxEntIRL
from qdil.rewards.builtin.pwil import PWIL
from qdil.rewards.builtin.true_reward import TrueReward
from qdil.rewards.builtin.wae import MCWAEGAIL, MCWAEWGAIL, WAEGAIL, WAEWGAIL, WAEReward

__all__ = [
    "AIRL",
    "GAIL",
    "GIRIL",
    "MCWAEGAIL",
    "MCWAEWGAIL",
    "PWIL",
    "WAEGAIL",
    "WAEWGAIL",
    "MaxEntIRL",
    "TrueReward",
    "WAEReward",
]
