"""qdil: quality-diversity imitation learning (WQDIL on PPGA) for MuJoCo locomotion.

``qdil.Experiment`` (a run driven from Python), ``qdil.open_run`` (a run folder read-only)
and ``qdil.load_recipe`` load on first use (PEP 562): ``import qdil`` imports no torch.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from qdil import numerics, threads

# before anything computes: same seed, same bits (docs/concepts/reproducibility.md)
numerics.configure()
# before an OpenMP pool starts: idle threads sleep rather than spin (docs/concepts/environments.md)
threads.configure()

from qdil.envs import register_envs  # noqa: E402

if TYPE_CHECKING:
    from qdil.experiment import Experiment
    from qdil.finished_run import FinishedRun, open_run
    from qdil.recipe_load import RecipeError, load_recipe

__version__ = "0.1.0"
__all__ = [
    "Experiment",
    "FinishedRun",
    "RecipeError",
    "__version__",
    "load_recipe",
    "open_run",
]

_HOMES = {
    "Experiment": "qdil.experiment",
    "FinishedRun": "qdil.finished_run",
    "open_run": "qdil.finished_run",
    "RecipeError": "qdil.recipe_load",
    "load_recipe": "qdil.recipe_load",
}

register_envs()


def __getattr__(name: str) -> Any:
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_HOMES[name]), name)
    globals()[name] = value  # looked up once
    return value
