"""pyribs' ``EvolutionStrategyEmitter`` with its ranker and strategy named by strings.

pyribs types ``ranker`` and ``es`` as "a callable or a name"; jsonargparse 4.53 writes such a
name back to a run's ``config.yaml`` as "Unable to serialize instance imp", which a resume
cannot read. This subclass takes the names only, so a recipe's gradient-free emitter
(sep-CMA-MAE) stores and resumes as written. Nothing else differs from pyribs'.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from ribs.archives import ArchiveBase
from ribs.emitters import EvolutionStrategyEmitter as RibsEvolutionStrategyEmitter


class EvolutionStrategyEmitter(RibsEvolutionStrategyEmitter):
    """pyribs' evolution-strategy emitter (CMA-ME, CMA-MAE, sep-CMA-MAE) over solutions.

    Args:
        archive: the archive it ranks by and restarts from.
        x0: (D,) the strategy's first mean.
        sigma0: the strategy's first step size.
        ranker: a pyribs ranker name (``imp``, ``2imp``, ``obj``, ...).
        es: a pyribs strategy name (``cma_es``, ``sep_cma_es``, ``lm_ma_es``, ``openai_es``).
        es_kwargs: extra arguments of the strategy.
        selection_rule: ``mu`` (the better half) or ``filter`` (the solutions added).
        restart_rule: ``no_improvement``, ``basic`` (the strategy's own stop) or every N
            iterations.
        batch_size: solutions per ``ask`` (``None``: the strategy's default).
        seed: the strategy's and ranker's seed.
    """

    def __init__(
        self,
        archive: ArchiveBase,
        *,
        x0: np.ndarray,
        sigma0: float,
        ranker: str = "2imp",
        es: str = "cma_es",
        es_kwargs: dict[str, Any] | None = None,
        selection_rule: Literal["mu", "filter"] = "filter",
        restart_rule: Literal["no_improvement", "basic"] | int = "no_improvement",
        batch_size: int | None = None,
        seed: int | None = None,
    ) -> None:
        super().__init__(
            archive,
            x0=x0,
            sigma0=sigma0,
            ranker=ranker,
            es=es,
            es_kwargs=es_kwargs,
            selection_rule=selection_rule,
            restart_rule=restart_rule,
            batch_size=batch_size,
            seed=seed,
        )
