"""What a reward pays for staying alive: reward per step before a fall and elsewhere.

:class:`SurvivalTally` sums, over an iteration's training rollouts, the rewards handed to
RL on the last :data:`WINDOW` steps before each termination and on every other step, and
counts the terminations. Why these figures: docs/concepts/survival.md.
"""

from __future__ import annotations

import torch

from qdil.data import Rollout
from qdil.reductions import sum_over

WINDOW = 20  # steps before a termination counted as "before the fall"


def before_termination(dones: torch.Tensor, terminated: torch.Tensor, window: int) -> torch.Tensor:
    """Which steps lie within ``window`` steps of their episode's termination.

    Steps of an episode that is truncated, or not over by the rollout's end, never do.

    Args:
        dones: (T, N) 1.0 where an episode ended at step t.
        terminated: (T, N) 1.0 where it ended by termination.
        window: steps counted before (and including) the terminal one.

    Returns:
        (T, N) bool.
    """
    near = torch.zeros(dones.shape, dtype=torch.bool, device=dones.device)
    # steps left to the episode's termination, counted backwards (inf: it ends otherwise)
    left = torch.full_like(dones[0], float("inf"))
    for t in reversed(range(dones.shape[0])):
        left = torch.where(dones[t] > 0, torch.full_like(left, float("inf")), left + 1)
        left = torch.where(terminated[t] > 0, torch.zeros_like(left), left)
        near[t] = left < window
    return near


class SurvivalTally:
    """Sums of one iteration's training rewards before falls and elsewhere.

    Args:
        window: steps before a termination that count as before the fall.
        prefix: prepended to the metrics' names after ``survival/``.
    """

    def __init__(self, window: int = WINDOW, prefix: str = "") -> None:
        self.window = window
        self.prefix = prefix
        # reward before falls, steps before falls, reward elsewhere, steps elsewhere, falls
        self.sums = torch.zeros(5, dtype=torch.float64)

    def add(self, rollout: Rollout, rewards: torch.Tensor) -> None:
        """Count a training rollout and the (T, N) rewards RL is handed for it."""
        valid = rollout.valid > 0
        near = before_termination(rollout.dones, rollout.terminated, self.window) & valid
        far = valid & ~near
        falls = (rollout.terminated > 0) & valid
        # sum_over: sums of up to 384,000 steps with the same bits on any thread count
        values = [
            sum_over(rewards[near].double(), 0),
            near.sum(),
            sum_over(rewards[far].double(), 0),
            far.sum(),
            falls.sum(),
        ]
        self.sums += torch.stack([torch.as_tensor(v, dtype=torch.float64).cpu() for v in values])

    def metrics(self) -> dict[str, float]:
        """The iteration's figures so far.

        Returns:
            ``survival/{prefix}reward_before_fall`` and ``survival/{prefix}reward_alive``
            (mean reward per step; NaN without such steps) and
            ``survival/{prefix}falls_per_1k_steps``.
        """
        near, near_steps, far, far_steps, falls = self.sums.tolist()
        steps = near_steps + far_steps
        figures = {
            "reward_before_fall": near / near_steps if near_steps else float("nan"),
            "reward_alive": far / far_steps if far_steps else float("nan"),
            "falls_per_1k_steps": 1000.0 * falls / steps if steps else float("nan"),
        }
        return {f"survival/{self.prefix}{name}": value for name, value in figures.items()}
