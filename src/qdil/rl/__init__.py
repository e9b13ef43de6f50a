"""Policies, normalisers, rollouts, GAE and VPPO (PPGA's vectorised PPO)."""

from typing import Any

__all__ = ["VPPO"]


def __getattr__(name: str) -> Any:
    # VPPO loads on first use: it imports the executors, which import this package's
    # rollouts, so an eager import here would make the two packages import each other
    if name == "VPPO":
        from qdil.rl.vppo import VPPO

        return VPPO
    raise AttributeError(name)
