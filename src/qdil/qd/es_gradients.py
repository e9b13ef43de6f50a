"""Evolution-strategy gradients: ∇f and ∇m_j at θ_μ from perturbed-policy episodes.

:class:`ESGradients` fills the loop's :class:`~qdil.seats.GradientEstimator` seat without
training anything: it plays mirrored perturbations θ_μ ± σε through the run's executor,
turns their objectives and measures into centred ranks and estimates every row of the
Jacobian from the same episodes (OpenAI-ES as dqd-rl's CMA-MEGA (ES) does). With PPGA's
emitter it makes CMA-MAEGA (ES). Why each choice: docs/concepts/es-gradients.md.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from qdil.data import Rollout
from qdil.qd.scoring import Scorer
from qdil.rl.collect import RewardFn
from qdil.rl.normalize import RunningMeanStd
from qdil.seats import PhaseResult

if TYPE_CHECKING:
    import torch

    from qdil.config import PolicyConfig
    from qdil.envs.vector import LocomotionVectorEnv
    from qdil.executors.base import Executor


def centered_ranks(values: np.ndarray) -> np.ndarray:
    """Each column's ranks, scaled to [-0.5, 0.5] (OpenAI-ES's fitness shaping).

    Args:
        values: (n, m) scores of n samples on m objectives, n ≥ 2.

    Returns:
        (n, m) float64: the lowest of a column -0.5, the highest 0.5; ties keep sample order.
    """
    n = len(values)
    ranks = np.empty(values.shape, dtype=np.float64)
    for j in range(values.shape[1]):
        ranks[np.argsort(values[:, j], kind="stable"), j] = np.arange(n)
    return ranks / (n - 1) - 0.5


def es_gradients(
    epsilon: np.ndarray, plus: np.ndarray, minus: np.ndarray, sigma: float, normalize: bool
) -> np.ndarray:
    """Mirrored-sampling gradient estimates of m objectives from centred ranks.

    ĝ_j = Σ_i ε_i (r⁺_ij − r⁻_ij) / (n σ), where r are the centred ranks of all 2n
    scores of objective j together.

    Args:
        epsilon: (n, D) the perturbation directions ε_i.
        plus: (n, m) scores of θ + σε_i.
        minus: (n, m) scores of θ − σε_i.
        sigma: the perturbation scale σ.
        normalize: scale each row to unit length (+1e-8 in the norm).

    Returns:
        (m, D) float64, one row per objective.
    """
    n = len(epsilon)
    ranks = centered_ranks(np.concatenate([plus, minus]))
    weights = ranks[:n] - ranks[n:]  # (n, m)
    gradients = weights.T @ epsilon.astype(np.float64) / (n * sigma)
    if normalize:
        gradients /= np.linalg.norm(gradients, axis=1, keepdims=True) + 1e-8
    return gradients


class ESGradients:
    """OpenAI-ES estimates of ∇f and ∇m_j; the walk steps θ_μ along them, no episodes.

    Defaults are dqd-rl's CMA-MEGA (ES) settings (``../shared/reference``: 50 mirrored
    pairs, σ = 0.02, one episode each, rows of unit length).

    Args:
        pairs: n, mirrored pairs θ_μ ± σε_i per iteration (2n policies played).
        sigma: σ, the perturbations' scale in parameter space.
        episodes: episodes per perturbed policy.
        deterministic: the perturbed policies act with their mean action (the parameter
            noise is the exploration) or sample.
        normalize: scale each gradient estimate to unit length.
    """

    def __init__(
        self,
        pairs: int = 50,
        sigma: float = 0.02,
        episodes: int = 1,
        deterministic: bool = True,
        normalize: bool = True,
    ) -> None:
        if pairs < 1:
            raise ValueError(f"rl.pairs must be at least 1, got {pairs}")
        if episodes < 1:
            raise ValueError(f"rl.episodes must be at least 1, got {episodes}")
        if not sigma > 0:
            raise ValueError(f"rl.sigma must be positive, got {sigma}")
        self.pairs, self.sigma, self.episodes = pairs, sigma, episodes
        self.deterministic, self.normalize = deterministic, normalize
        self._at: np.ndarray | None = None  # θ_μ of the last estimate
        self._gradients: np.ndarray | None = None  # (k+1, D) there
        self._rollouts: list[Rollout] = []

    @property
    def eval_slots(self) -> int:
        """Simulations one estimate plays at once (the run's evaluation env holds them)."""
        return 2 * self.pairs * self.episodes

    def setup(
        self,
        train_env: LocomotionVectorEnv,
        executor: Executor,
        policy: PolicyConfig,
        generator: torch.Generator,
        seed: int,
    ) -> None:
        """Bind the executor whose evaluation simulations play the perturbations.

        ``train_env`` gives the sizes and device only: no training rollouts are played.
        """
        self.scorer = Scorer(executor, train_env, policy, generator)
        self.num_objectives = train_env.num_feet + 1

    def compute_jacobian(
        self, theta: np.ndarray, stats: RunningMeanStd, reward_fn: RewardFn, seed: int
    ) -> PhaseResult:
        """Estimate the (k+1, D) Jacobian at θ_μ from 2n perturbed policies' episodes.

        Args:
            theta: (D,) search policy θ_μ.
            stats: its observation statistics (one policy; every perturbation plays with
                them, frozen).
            reward_fn: per-step reward of the objective f, (T, N) from a rollout; its
                rollouts are kept for the reward model's update.
            seed: draws ε and resets the simulations.

        Returns:
            ``solutions`` θ_μ + ĝ_j (the Jacobian is ``solutions - theta``).
        """
        theta = np.asarray(theta, dtype=np.float64)
        epsilon = np.random.default_rng(seed).standard_normal((self.pairs, theta.size))
        noise = self.sigma * epsilon
        solutions = np.concatenate([theta + noise, theta - noise])
        rollouts: list[Rollout] = []

        def recorded(rollout: Rollout):
            rollouts.append(rollout)
            return reward_fn(rollout)

        played = self.scorer.evaluate(
            solutions,
            RunningMeanStd.stack([stats] * len(solutions)),
            self.episodes,
            seed,
            recorded,
            self.deterministic,
        )
        scores = np.column_stack([played.objective, played.measures])  # (2n, k+1)
        gradients = es_gradients(
            epsilon, scores[: self.pairs], scores[self.pairs :], self.sigma, self.normalize
        )
        self._at, self._gradients, self._rollouts = theta, gradients, rollouts
        diagnostics = {
            "objective_mean": float(played.objective.mean()),
            "objective_std": float(played.objective.std()),
            "true_return_mean": float(played.true_objective.mean()),
            "episode_length": float(played.lengths.mean()),
        }
        copies = RunningMeanStd.stack([stats] * self.num_objectives)
        return PhaseResult(theta + gradients, copies, rollouts, diagnostics, played.env_steps)

    def walk(
        self,
        theta: np.ndarray,
        stats: RunningMeanStd,
        coefficients: np.ndarray,
        reward_fn: RewardFn,
        seed: int,
    ) -> PhaseResult:
        """θ_μ + Σ_j c_j ĝ_j, with the last estimate's ĝ (CMA-MEGA's gradient step).

        A θ_μ the emitter restarted at an elite since the estimate does not move: the
        estimate belongs to the old θ_μ. The reward model updates on the estimate's
        perturbation episodes (``rollouts``); the walk plays none.

        Args:
            theta: (D,) search policy θ_μ.
            stats: its observation statistics (kept).
            coefficients: (k+1,) gradient coefficients c, the emitter's mean.
            reward_fn: unused: the step plays no episode.
            seed: unused.
        """
        theta = np.asarray(theta, dtype=np.float64)
        step = np.zeros_like(theta)
        if self._at is not None and np.array_equal(theta, self._at):
            step = np.asarray(coefficients, dtype=np.float64) @ self._gradients
        diagnostics = {"step_norm": float(np.linalg.norm(step))}
        return PhaseResult((theta + step)[None], stats, self._rollouts, diagnostics, 0)

    def state_dict(self) -> dict:
        """Nothing outlives an iteration: ε comes from the loop's seeds."""
        return {}

    def load_state_dict(self, state: dict) -> None:
        """Nothing to restore (:meth:`state_dict`)."""
