"""The PPGA emitter: branch the search policy along VPPO's gradient estimates.

:class:`PPGAEmitter` normalises VPPO's Jacobian (``tell_dqd``), proposes branches
θ_μ + Σ_j c_ij ĝ_j with coefficients from an evolution strategy (``ask``; :func:`resolve_es`),
ranks them by archive improvement and restarts θ_μ at an elite when none improved (``tell``).
The QD loop's walk moves θ_μ and hands it back (:attr:`PPGAEmitter.theta`). Why:
docs/concepts/loop.md.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any, Literal

import numpy as np
from ribs.archives import ArchiveBase
from ribs.emitters import EmitterBase
from ribs.emitters.opt import (
    CMAEvolutionStrategy,
    EvolutionStrategyBase,
    LMMAEvolutionStrategy,
    OpenAIEvolutionStrategy,
    SeparableCMAEvolutionStrategy,
)
from ribs.emitters.rankers import RankerBase, _get_ranker

from qdil.qd.xnes import XNES

EVOLUTION_STRATEGIES: dict[str, type[EvolutionStrategyBase]] = {
    "xnes": XNES,
    "cma_es": CMAEvolutionStrategy,
    "sep_cma_es": SeparableCMAEvolutionStrategy,
    "lm_ma_es": LMMAEvolutionStrategy,
    "openai_es": OpenAIEvolutionStrategy,
}


def resolve_es(es: str | type[EvolutionStrategyBase]) -> type[EvolutionStrategyBase]:
    """An evolution strategy class from a short name, a ``module.Class`` path or a class.

    Raises:
        ValueError: if the name is unknown or the class is not an ``EvolutionStrategyBase``.
    """
    if isinstance(es, str):
        if es in EVOLUTION_STRATEGIES:
            es = EVOLUTION_STRATEGIES[es]
        elif "." in es:
            module, _, name = es.rpartition(".")
            es = getattr(importlib.import_module(module), name)
        else:
            raise ValueError(
                f"qd.emitter.es: unknown evolution strategy {es!r}; use one of "
                f"{', '.join(EVOLUTION_STRATEGIES)} or a class path"
            )
    if not (isinstance(es, type) and issubclass(es, EvolutionStrategyBase)):
        raise ValueError(f"qd.emitter.es: {es!r} is not a ribs EvolutionStrategyBase subclass")
    return es


class PPGAEmitter(EmitterBase):
    """Branches θ_μ with coefficients from an evolution strategy (PPGA, Batra et al. 2023).

    Args:
        archive: the CMA-MAE archive that ranks and restarts the emitter.
        x0: (D,) initial search policy θ_0.
        sigma0: initial step size of the coefficient distribution (PPGA: Walker2d and
            HalfCheetah 1.0, Humanoid 0.5).
        batch_size: λ, branches per iteration (PPGA: 300).
        es: evolution strategy over the k+1 coefficients: ``"xnes"`` (PPGA), a pyribs name
            (``"cma_es"``, ...), a ``module.Class`` path or a class.
        es_kwargs: extra arguments of the strategy.
        ranker: pyribs ranker of the branches (PPGA: ``"imp"``, improvement only).
        restart_rule: ``"no_improvement"`` restarts when no branch changed the archive;
            ``"basic"`` only on the strategy's own stop check.
        initial_mean: where the strategy's mean starts and restarts: ``"uniform"`` draws
            c_0 ∈ [0, 2] and c_j ∈ [-2, 2] (PPGA's evotorch bounds), ``"zero"`` is μ = 0
            (the paper's Alg. 1 restart).
        normalize_grad: divide each Jacobian row by its norm.
        epsilon: added to the norms.
        theta_fields: extra archive fields of θ_0 (its observation statistics).
        seed: seed of the strategy, the ranker and the initial means.

    Raises:
        ValueError: for a bad shape, strategy, ranker or rule.
    """

    theta_fields: dict[str, np.ndarray]
    """Extra archive fields of θ_μ (its observation statistics), which the loop reads and sets."""
    restarts: int
    """How many times θ_μ restarted at an elite (or, while the archive is empty, the strategy)."""

    def __init__(
        self,
        archive: ArchiveBase,
        x0: np.ndarray,
        *,
        sigma0: float = 1.0,
        batch_size: int = 300,
        es: str | type[EvolutionStrategyBase] = "xnes",
        es_kwargs: dict[str, Any] | None = None,
        ranker: str | Callable[..., RankerBase] = "imp",
        restart_rule: Literal["no_improvement", "basic"] = "no_improvement",
        initial_mean: Literal["uniform", "zero"] = "uniform",
        normalize_grad: bool = True,
        epsilon: float = 1e-8,
        theta_fields: dict[str, np.ndarray] | None = None,
        seed: int | None = None,
    ) -> None:
        super().__init__(
            archive,
            solution_dim=archive.solution_dim,
            bounds=None,
            lower_bounds=None,
            upper_bounds=None,
        )
        if restart_rule not in ("no_improvement", "basic"):
            raise ValueError(
                f"qd.emitter.restart_rule must be no_improvement or basic, got {restart_rule!r}"
            )
        if initial_mean not in ("uniform", "zero"):
            raise ValueError(
                f"qd.emitter.initial_mean must be uniform or zero, got {initial_mean!r}"
            )
        es_seed, ranker_seed, mean_seed = np.random.SeedSequence(seed).spawn(3)
        self._theta = np.asarray(x0, dtype=archive.dtypes["solution"]).copy()
        if self._theta.shape != (archive.solution_dim,):
            raise ValueError(
                f"x0 must have shape ({archive.solution_dim},), got {self._theta.shape}"
            )
        self.theta_fields = dict(theta_fields or {})
        self._num_coefficients = archive.measure_dim + 1
        self._normalize_grad = normalize_grad
        self._epsilon = epsilon
        self._restart_rule = restart_rule
        self._initial_mean = initial_mean
        self._rng = np.random.default_rng(mean_seed)
        self._ranker = _get_ranker(ranker, ranker_seed)
        self._ranker.reset(self, archive)
        self._es = resolve_es(es)(
            sigma0=sigma0,
            solution_dim=self._num_coefficients,
            batch_size=batch_size,
            seed=es_seed,
            dtype=np.float64,
            lower_bounds=-np.inf,
            upper_bounds=np.inf,
            **(es_kwargs or {}),
        )
        self._es.reset(self._draw_mean())
        self._batch_size = self._es.batch_size
        self._jacobian: np.ndarray | None = None
        self._proposed: np.ndarray | None = None
        self.restarts = 0
        self.itrs = 0
        self.last_improved = 0

    def _draw_mean(self) -> np.ndarray:
        if self._initial_mean == "zero":
            return np.zeros(self._num_coefficients)
        low = np.r_[0.0, np.full(self._num_coefficients - 1, -2.0)]
        return self._rng.uniform(low, 2.0)

    @property
    def batch_size(self) -> int:
        """λ, branches per ``ask``."""
        return self._batch_size

    @property
    def batch_size_dqd(self) -> int:
        """One search point per ``ask_dqd``."""
        return 1

    @property
    def theta(self) -> np.ndarray:
        """(D,) the search policy θ_μ."""
        return self._theta

    def move(self, solution: np.ndarray, fields: dict[str, np.ndarray]) -> None:
        """θ_μ moves to where the estimator's walk ended (PPGA's outer step).

        Args:
            solution: (D,) the walked θ_μ.
            fields: its observation statistics (``obs_mean`` (obs_dim,), ``obs_var``
                (obs_dim,), ``obs_count`` ()), the archive's extra fields of θ_μ.
        """
        self._theta = np.asarray(solution, dtype=self._theta.dtype).reshape(self._theta.shape)
        self.theta_fields = dict(fields)

    @property
    def coefficient_mean(self) -> np.ndarray:
        """(k+1,) the strategy's mean μ: the walk's weights of r and δ_1..δ_k."""
        return np.asarray(self._es.mean, dtype=np.float64).copy()

    @property
    def es(self) -> EvolutionStrategyBase:
        """The evolution strategy over gradient coefficients."""
        return self._es

    def ask_dqd(self) -> np.ndarray:
        """(1, D) the search policy θ_μ."""
        return self._theta[None].copy()

    def tell_dqd(
        self,
        solution: np.ndarray,
        objective: np.ndarray,
        measures: np.ndarray,
        jacobian: np.ndarray,
        add_info: dict[str, np.ndarray],
        **fields: np.ndarray,
    ) -> None:
        """Store the (1, k+1, D) Jacobian at θ_μ, each row normalised."""
        self._jacobian = self._normalized(jacobian)

    def _normalized(self, jacobian: np.ndarray) -> np.ndarray:
        """(k+1, D) rows of a (1, k+1, D) Jacobian, each divided by its norm if asked."""
        jacobian = np.asarray(jacobian, dtype=np.float64).copy()
        expected = (1, self._num_coefficients, self.solution_dim)
        if jacobian.shape != expected:
            raise ValueError(f"jacobian must have shape {expected}, got {jacobian.shape}")
        if self._normalize_grad:
            jacobian /= np.linalg.norm(jacobian, axis=2, keepdims=True) + self._epsilon
        return jacobian[0]

    def propose(self, jacobian: np.ndarray) -> np.ndarray:
        """(λ, D) the branches the next ``ask`` returns, drawn now from the (1, k+1, D) Jacobian.

        The branches depend on the Jacobian and the strategy only, not on θ_μ's score, so
        the QD loop can score θ_μ and its branches in one batch: it proposes, evaluates
        both, then calls ``tell_dqd`` (with the same Jacobian) and ``ask`` as usual.
        """
        self._jacobian = self._normalized(jacobian)
        self._proposed = self._branch()
        return self._proposed.copy()

    def ask(self) -> np.ndarray:
        """(λ, D) branches θ_μ + Σ_j c_ij ĝ_j with c_i from the strategy (or those proposed)."""
        if self._jacobian is None:
            raise RuntimeError("call ask_dqd() and tell_dqd() before ask()")
        proposed, self._proposed = getattr(self, "_proposed", None), None
        return self._branch() if proposed is None else proposed

    def _branch(self) -> np.ndarray:
        assert self._jacobian is not None
        self.coefficients = self._es.ask()
        return (self._theta + self.coefficients @ self._jacobian).astype(self._theta.dtype)

    def tell(
        self,
        solution: np.ndarray,
        objective: np.ndarray,
        measures: np.ndarray,
        add_info: dict[str, np.ndarray],
        **fields: np.ndarray,
    ) -> None:
        """Rank the branches, update the strategy, restart if nothing improved the archive."""
        if self._jacobian is None:
            raise RuntimeError("call ask_dqd(), tell_dqd() and ask() before tell()")
        self.itrs += 1
        data = {"solution": solution, "objective": objective, "measures": measures, **fields}
        improved = int(np.asarray(add_info["status"]).astype(bool).sum())
        self.last_improved = improved
        indices, values = self._ranker.rank(self, self.archive, data, add_info)
        self._es.tell(indices, values, improved)
        stop = self._es.check_stop(np.asarray(values)[indices])
        if stop or (self._restart_rule == "no_improvement" and improved == 0):
            self.restart()

    def restart(self) -> None:
        """θ_μ ← a uniformly random elite (with its own statistics); fresh strategy.

        While the archive is still empty (no return above ``threshold_min`` yet), θ_μ stays
        where it is and only the strategy restarts.
        """
        if not self.archive.empty:
            elite = self.archive.sample_elites(1)
            self._theta = np.asarray(elite["solution"][0], dtype=self._theta.dtype).copy()
            reserved = {"solution", "objective", "measures", "threshold", "index", "length"}
            self.theta_fields = {
                k: np.asarray(v[0]).copy() for k, v in elite.items() if k not in reserved
            }
        self._es.reset(self._draw_mean())
        self._ranker.reset(self, self.archive)
        self.restarts += 1
