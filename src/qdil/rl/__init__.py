"""Policies, normalisers, rollouts, GAE and VPPO (PPGA's vectorised PPO)."""

from qdil.rl.vppo import VPPO

__all__ = ["VPPO"]
