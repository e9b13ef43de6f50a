"""How qdil's worker threads wait: OpenMP threads sleep when they run out of work.

numba's physics and inference pools and torch's intra-op pool are GNU OpenMP, whose idle
threads spin by default; on a core another process needs, a spinning thread takes the time
its sibling was to compute with. ``import qdil`` sets ``OMP_WAIT_POLICY`` (default
``PASSIVE``) before either pool starts; why and what it costs: docs/concepts/environments.md.
"""

from __future__ import annotations

import os

ENV = "OMP_WAIT_POLICY"
DEFAULT_POLICY = "PASSIVE"


def configure() -> None:
    """Set ``OMP_WAIT_POLICY`` to ``PASSIVE`` unless the environment sets it already.

    The processes this one starts (trials, Ray workers) inherit it. OpenMP reads it once,
    when its runtime loads: at ``import torch`` for torch's pool. A process that imported
    torch before qdil keeps the policy it started with.
    """
    os.environ.setdefault(ENV, DEFAULT_POLICY)
