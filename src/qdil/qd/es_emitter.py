"""pyribs' ``EvolutionStrategyEmitter`` with its ranker and strategy named by strings.

pyribs types ``ranker`` and ``es`` as "a callable or a name"; jsonargparse 4.53 writes such a
name back to a run's ``config.yaml`` as "Unable to serialize instance imp", which a resume
cannot read. This subclass takes the names only, so a recipe's gradient-free emitter
(sep-CMA-MAE) stores and resumes as written. One more difference: a restart while the
archive is still empty (nothing passed ``threshold_min`` yet) starts again from ``x0``,
where pyribs 0.12 would sample an elite from the empty archive and fail.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from ribs._utils import validate_batch
from ribs.archives import ArchiveBase
from ribs.emitters import EvolutionStrategyEmitter as RibsEvolutionStrategyEmitter
from typing_extensions import override


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

    @override
    def tell(self, solution, objective, measures, add_info, **fields) -> None:
        """As pyribs' ``tell`` (0.12), except that a restart from an empty archive goes to x0.

        Args:
            solution: (batch_size, D) the solutions of the last :meth:`ask`.
            objective: (batch_size,) their objectives.
            measures: (batch_size, m) their measures.
            add_info: what the archive's ``add`` returned for them.
            fields: their extra archive fields.
        """
        data, add_info = validate_batch(
            self.archive,
            {"solution": solution, "objective": objective, "measures": measures, **fields},
            add_info,
        )
        self._itrs += 1
        new_sols = add_info["status"].astype(bool).sum()
        indices, ranking_values = self._ranker.rank(self, self.archive, data, add_info)
        num_parents = new_sols if self._selection_rule == "filter" else self._batch_size // 2
        self._opt.tell(indices, ranking_values, num_parents)
        if self._opt.check_stop(ranking_values[indices]) or self._check_restart(new_sols):
            empty = self.archive.empty  # nothing passed threshold_min yet
            new_x0 = self.x0 if empty else self.archive.sample_elites(1)["solution"][0]
            self._opt.reset(new_x0)
            self._ranker.reset(self, self.archive)
            self._restarts += 1
