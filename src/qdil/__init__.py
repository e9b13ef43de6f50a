"""qdil: quality-diversity imitation learning (WQDIL on PPGA) for MuJoCo locomotion."""

from __future__ import annotations

from qdil.envs import register_envs

__version__ = "0.1.0"

register_envs()
