"""Exponential natural evolution strategies (xNES), as a pyribs evolution strategy.

:class:`XNES` is a :class:`ribs.emitters.opt.EvolutionStrategyBase`, since pyribs ships no
xNES (decision D11); PPGA samples its gradient coefficients from it. Its defaults and update:
docs/concepts/loop.md (section "xNES").
"""

from __future__ import annotations

import numpy as np
from numpy.typing import DTypeLike
from ribs.emitters.opt import EvolutionStrategyBase


def nes_utilities(num: int) -> np.ndarray:
    """(num,) NES rank utilities, best rank first; they sum to 0."""
    ranks = np.arange(1, num + 1)
    raw = np.maximum(0.0, np.log(num / 2 + 1) - np.log(ranks))
    return raw / raw.sum() - 1.0 / num


class XNES(EvolutionStrategyBase):
    """xNES over a ``solution_dim``-dimensional space (for PPGA: the k+1 coefficients).

    Args:
        sigma0: initial step size σ.
        solution_dim: dimension n.
        batch_size: samples per ``ask``; ``None`` for 4 + ⌊3 ln n⌋.
        seed: seed or ``SeedSequence`` of the sampler.
        dtype: dtype of the samples.
        lower_bounds: must be -inf (bounded xNES is not implemented).
        upper_bounds: must be inf.
        center_learning_rate: η_μ.
        stdev_learning_rate: η_σ; ``None`` for 0.6 (3 + ln n) / (n √n).
        b_learning_rate: η_B; ``None`` for the same default.

    Raises:
        ValueError: for finite bounds or non-positive sizes.
    """

    def __init__(
        self,
        sigma0: float,
        solution_dim: int,
        batch_size: int | None = None,
        seed: int | np.random.SeedSequence | None = None,
        dtype: DTypeLike = np.float64,
        lower_bounds: float | np.ndarray = -np.inf,
        upper_bounds: float | np.ndarray = np.inf,
        center_learning_rate: float = 1.0,
        stdev_learning_rate: float | None = None,
        b_learning_rate: float | None = None,
    ) -> None:
        if np.any(np.isfinite(lower_bounds)) or np.any(np.isfinite(upper_bounds)):
            raise ValueError("XNES does not support solution bounds; pass -inf and inf")
        if solution_dim < 1 or sigma0 <= 0:
            raise ValueError(f"need solution_dim >= 1 and sigma0 > 0, got {solution_dim}, {sigma0}")
        n = solution_dim
        self.sigma0 = float(sigma0)
        self.solution_dim = n
        self.batch_size = 4 + int(3 * np.log(n)) if batch_size is None else int(batch_size)
        if self.batch_size < 2:
            raise ValueError(f"batch_size must be at least 2, got {batch_size}")
        self.dtype = np.dtype(dtype)
        default_lr = 0.6 * (3 + np.log(n)) / (n * np.sqrt(n))
        self.center_learning_rate = center_learning_rate
        self.stdev_learning_rate = (
            default_lr if stdev_learning_rate is None else stdev_learning_rate
        )
        self.b_learning_rate = default_lr if b_learning_rate is None else b_learning_rate
        self._rng = np.random.default_rng(seed)
        self.reset(np.zeros(n))

    def reset(self, x0: np.ndarray) -> None:
        """Restart at mean ``x0`` with σ = σ0 and B = I."""
        self.mean = np.array(x0, dtype=np.float64).reshape(self.solution_dim)
        self.sigma = self.sigma0
        self.b = np.eye(self.solution_dim)
        self._z: np.ndarray | None = None

    @property
    def covariance(self) -> np.ndarray:
        """(n, n) covariance σ² B Bᵀ of the search distribution."""
        return self.sigma**2 * self.b @ self.b.T

    def ask(self, batch_size: int | None = None) -> np.ndarray:
        """(batch_size, n) samples μ + σ B z with z ~ N(0, I)."""
        size = self.batch_size if batch_size is None else int(batch_size)
        self._z = self._rng.standard_normal((size, self.solution_dim))
        return (self.mean + self.sigma * self._z @ self.b.T).astype(self.dtype)

    def tell(
        self, ranking_indices: np.ndarray, ranking_values: np.ndarray, num_parents: int
    ) -> None:
        """Natural-gradient step from the ranking of the last ``ask`` (best first).

        ``num_parents`` is unused: xNES weighs every sample by its rank utility.
        """
        if self._z is None:
            raise RuntimeError("call ask() before tell()")
        z = self._z[np.asarray(ranking_indices)]
        u = nes_utilities(len(z))
        n = self.solution_dim
        grad_delta = u @ z
        grad_m = (z.T * u) @ z - u.sum() * np.eye(n)
        grad_sigma = np.trace(grad_m) / n
        grad_b = grad_m - grad_sigma * np.eye(n)
        self.mean = self.mean + self.center_learning_rate * self.sigma * self.b @ grad_delta
        self.sigma = self.sigma * np.exp(0.5 * self.stdev_learning_rate * grad_sigma)
        self.b = self.b @ _expm_symmetric(0.5 * self.b_learning_rate * grad_b)
        self._z = None

    def check_stop(self, ranking_values: np.ndarray) -> bool:
        """Stop on a non-finite or collapsed distribution, or on a flat ranking.

        PPGA's own check compared unsorted values and never fired (quirk Q6); this one
        restarts when the samples' improvement values are all equal, when σ·‖B‖ falls
        below 1e-12, or when B's condition number exceeds 1e14.
        """
        if not (
            np.isfinite(self.mean).all() and np.isfinite(self.b).all() and np.isfinite(self.sigma)
        ):
            return True
        singular = np.linalg.svd(self.b, compute_uv=False)
        if self.sigma * singular[0] < 1e-12 or singular[0] / singular[-1] > 1e14:
            return True
        values = np.asarray(ranking_values, dtype=np.float64)
        return bool(values.size > 1 and np.ptp(values) < 1e-12)


def _expm_symmetric(matrix: np.ndarray) -> np.ndarray:
    """Exp of a symmetric matrix by eigendecomposition (exact, and cheaper than Padé)."""
    eigenvalues, eigenvectors = np.linalg.eigh(0.5 * (matrix + matrix.T))
    return (eigenvectors * np.exp(eigenvalues)) @ eigenvectors.T
