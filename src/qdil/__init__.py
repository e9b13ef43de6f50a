"""qdil: quality-diversity imitation learning (WQDIL on PPGA) for MuJoCo locomotion."""

from __future__ import annotations

from qdil import numerics

# before anything computes: same seed, same bits (docs/concepts/reproducibility.md)
numerics.configure()

from qdil.envs import register_envs  # noqa: E402

__version__ = "0.1.0"

register_envs()
