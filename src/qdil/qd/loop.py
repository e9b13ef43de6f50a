"""``run_qd``: the QD-IL loop (the paper's Algorithm 1), one explicit iteration at a time.

Each iteration:

1. ``ask_dqd`` gives the search policy θ_μ; the gradient estimator (VPPO) estimates ∇f and
   ∇m at θ_μ with rewards from the reward model; the emitter proposes λ branches
   θ_μ + Σ c_j ĝ_j.
2. The run's scorer plays θ_μ and the branches (side by side where the executor can: the
   branches do not depend on θ_μ's score); ``tell_dqd`` inserts θ_μ with its Jacobian,
   ``ask`` returns the proposed branches, ``tell`` inserts them, ranks the coefficients by
   archive improvement and adapts xNES (or restarts θ_μ at a random elite when nothing
   improved).
3. The estimator walks θ_μ along c_0·r̂ + Σ c_j·δ_j with c the xNES mean.
4. The reward model updates once on expert transitions and this iteration's policy
   transitions (decision D3).
5. Metrics are logged and, every K iterations, a checkpoint is written.

The CMA-MAE archive and xNES see returns under the reward model (+bonus); every
evaluation also records the true return into the passive ``true`` archive, which gives
all reported metrics (decision D1).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from qdil.config import finished
from qdil.data import Rollout, TransitionBatch
from qdil.qd.archives import QD_OFFSETS, qd_metrics
from qdil.qd.checkpoint import save_checkpoint
from qdil.qd.iteration_reward import TrainReward, reward_functions, update_reward, walk_survival
from qdil.qd.search import search_emitters
from qdil.rl.episodes import Evaluation
from qdil.rl.normalize import RunningMeanStd, fields_from_stats, stats_from_fields
from qdil.timing import ARCHIVE_WORK, Stopwatch, section

if TYPE_CHECKING:
    from qdil.config import LoggingConfig, QDConfig
    from qdil.qd.archives import RunArchives
    from qdil.qd.state import LoopState, Run
    from qdil.seats import PhaseResult, SearchEmitter


@contextmanager
def quiet_empty_archive() -> Iterator[None]:
    """Silence pyribs' warning that an insertion left the CMA-MAE archive empty.

    pyribs warns "`archive` was empty before adding solutions, and it is still empty ...
    `threshold_min` is too high" whenever no solution beats ``threshold_min``. Until a return
    passes it that is the expected state, not a fault: the PPGA recipes keep PPGA's
    ``threshold_min: 200``, which the untrained θ_μ's return stays below at iteration 1, and
    the emitter keeps θ_μ and restarts its strategy until an elite exists. The ``qd/*``
    metrics come from the passive true archive, which has no threshold.
    """
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="`archive` was empty before adding solutions")
        yield


def _objective(fitness: str, evaluation: Evaluation) -> np.ndarray:
    """(n,) what the archive ranks by: the learned return, or the true one (``qd.fitness``)."""
    return evaluation.true_objective if fitness == "true" else evaluation.objective


def _iteration_rewards(run: Run) -> tuple[TrainReward, Any]:
    """This iteration's training and evaluation rewards (``reward_functions`` of the run's)."""
    return reward_functions(
        run.reward,
        run.state.iteration,
        run.eval_env.max_episode_steps,
        getattr(run.estimator, "gamma", None),
        scores_learned=not (run.qd.fitness == "true" or run.reward.is_true_reward),
    )


def qd_iteration(run: Run) -> dict[str, float]:
    """One iteration of Algorithm 1; returns its metrics.

    Without an estimator (``rl: null``) one of :func:`gradient_free_iteration` instead.
    """
    if run.estimator is None:
        return gradient_free_iteration(run)
    state, estimator, scheduler, emitter = run.state, run.estimator, run.scheduler, run.emitter
    train_reward, eval_reward = _iteration_rewards(run)
    qd = run.qd
    watch = Stopwatch()

    # ---- 1. gradients at θ_μ; the branches along them
    with watch("jacobian"):
        with section(ARCHIVE_WORK):
            theta = scheduler.ask_dqd()[0]
        stats = stats_from_fields(emitter.theta_fields)
        jacobian_phase = estimator.compute_jacobian(theta, stats, train_reward, state.next_seed())
        jacobian = (jacobian_phase.solutions.astype(np.float64) - theta)[None]
    branches = emitter.propose(jacobian)  # what scheduler.ask() returns below
    branch_stats = RunningMeanStd.stack([stats] * len(branches))

    # ---- 2. score θ_μ and the branches (one batch where the executor can), insert θ_μ,
    # then the branches; rank the coefficients by archive improvement and adapt xNES
    with watch("evaluate"):
        mean_eval, evaluation = run.scorer.evaluate_all(
            [
                (theta[None], stats, qd.mean_episodes, state.next_seed()),
                (branches, branch_stats, qd.branch_episodes, state.next_seed()),
            ],
            eval_reward,
            qd.deterministic_eval,
        )
    fields = fields_from_stats(stats, mean_eval.lengths)
    objective = _objective(qd.fitness, mean_eval)  # learned, or true with fitness true
    with quiet_empty_archive(), section(ARCHIVE_WORK):
        scheduler.tell_dqd(objective, mean_eval.measures, jacobian, **fields)
    run.archives.add(theta[None], objective, mean_eval.true_objective, mean_eval.measures, fields)
    with section(ARCHIVE_WORK):
        asked = scheduler.ask()
    if not np.array_equal(asked, branches):
        raise RuntimeError("the scheduler's ask() differs from the emitter's proposal")
    fields = fields_from_stats(branch_stats, evaluation.lengths)
    restarts = emitter.restarts
    objective = _objective(qd.fitness, evaluation)
    with quiet_empty_archive(), section(ARCHIVE_WORK):
        scheduler.tell(objective, evaluation.measures, **fields)
    run.archives.add(branches, objective, evaluation.true_objective, evaluation.measures, fields)

    # ---- 3. walk θ_μ along the coefficient mean
    with watch("walk"):
        coefficients = np.array(emitter.coefficient_mean)  # what the walk is handed
        train_reward.returned.clear()
        walk = estimator.walk(
            emitter.theta,
            stats_from_fields(emitter.theta_fields),
            coefficients,
            train_reward,
            state.next_seed(),
        )
        walked = fields_from_stats(walk.stats, [0.0])
        emitter.move(walk.solutions[0], {k: v[0] for k, v in walked.items() if k != "length"})

    # ---- 4. reward model update (once per iteration, on this iteration's policy data);
    # fixed rewards return {}, the bonus wrapper still reports its counts
    with watch("reward_update"):
        policy = TransitionBatch.cat([r.transitions() for r in walk.rollouts])
        expert = run.expert
        if run.reward.needs_log_probs:  # AIRL: both batches under the walked θ_μ
            logp = partial(run.scorer.log_probs, walk.solutions[0], walk.stats)
            expert = replace(expert, log_probs=logp(expert.obs, expert.actions))
            policy = replace(policy, log_probs=logp(policy.obs, policy.actions))
        reward_metrics = update_reward(run.reward, state.iteration, expert, policy)

    # ---- 5. metrics
    steps = jacobian_phase.env_steps + walk.env_steps + mean_eval.env_steps + evaluation.env_steps
    seconds = time.perf_counter() - watch.start
    state.count(steps, seconds)
    learned = not run.reward.is_true_reward
    metrics = _archive_metrics(run.archives, run.task, learned)
    returns, _ = run.executor.pop_episode_stats()
    metrics |= _training_metrics(returns, reward_metrics, train_reward, learned)
    metrics |= _throughput(state, steps, seconds)
    metrics |= walk_survival(walk.rollouts, train_reward.returned, coefficients)
    metrics |= _search_metrics(emitter, jacobian_phase, walk, mean_eval, qd.fitness, restarts)
    return metrics | watch.metrics()


def _search_metrics(
    emitter: SearchEmitter,
    jacobian: PhaseResult,
    walk: PhaseResult,
    mean_eval: Evaluation,
    fitness: str,
    restarts: int,
) -> dict[str, float]:
    """The estimator's diagnostics, θ_μ's scores and measures, the emitter's state.

    Args:
        emitter: the search emitter, after the iteration's walk.
        jacobian: the Jacobian phase.
        walk: the walk.
        mean_eval: θ_μ's evaluation.
        fitness: ``qd.fitness``, what θ_μ's objective is.
        restarts: the emitter's restarts before this iteration's ``tell``.
    """
    metrics = {f"rl/jacobian_{k}": v for k, v in jacobian.diagnostics.items()}
    metrics |= {f"rl/walk_{k}": v for k, v in walk.diagnostics.items()}
    metrics |= {
        "search/objective": float(_objective(fitness, mean_eval)[0]),
        "search/true_objective": float(mean_eval.true_objective[0]),
        "emitter/restarts": float(emitter.restarts),
        "emitter/restarted": float(emitter.restarts > restarts),
        "emitter/improved": float(getattr(emitter, "last_improved", np.nan)),
    }
    for j, value in enumerate(mean_eval.measures[0]):
        metrics[f"search/measure_{j}"] = float(value)
    for j, value in enumerate(emitter.coefficient_mean):
        metrics[f"emitter/coefficient_{j}"] = float(value)
    return metrics


def gradient_free_iteration(run: Run) -> dict[str, float]:
    """One iteration without an estimator (``rl: null``: sep-CMA-MAE); returns its metrics.

    The scheduler's emitters ask for solutions, the scorer plays them (observation
    statistics of θ_0, never updated: no episode trains them), the scheduler tells them
    the results; the reward model updates on these evaluation episodes, whose visits the
    bonus counts.
    """
    state, scheduler, qd = run.state, run.scheduler, run.qd
    train_reward, eval_reward = _iteration_rewards(run)
    tic = time.perf_counter()
    with section(ARCHIVE_WORK):
        solutions = scheduler.ask()
    stats = RunningMeanStd(len(solutions), (run.scorer.obs_dim,))
    rollouts: list[Rollout] = []

    def recorded(rollout: Rollout) -> torch.Tensor:
        rollouts.append(rollout)
        return eval_reward(rollout)

    evaluation = run.scorer.evaluate(
        solutions,
        stats,
        qd.branch_episodes,
        state.next_seed(),
        None if eval_reward is None else recorded,
        qd.deterministic_eval,
    )
    fields = fields_from_stats(stats, evaluation.lengths)
    objective = _objective(qd.fitness, evaluation)
    with quiet_empty_archive(), section(ARCHIVE_WORK):
        scheduler.tell(objective, evaluation.measures, **fields)
    run.archives.add(solutions, objective, evaluation.true_objective, evaluation.measures, fields)

    reward_metrics: dict[str, float] = {}
    if rollouts:  # a learned reward: count the visits, then learn from the episodes
        for rollout in rollouts:
            train_reward(rollout)
        policy = TransitionBatch.cat([r.transitions() for r in rollouts])
        reward_metrics = update_reward(run.reward, state.iteration, run.expert, policy)
    seconds = time.perf_counter() - tic
    state.count(evaluation.env_steps, seconds)
    learned = not run.reward.is_true_reward
    metrics = _archive_metrics(run.archives, run.task, learned)
    returns, _ = run.executor.pop_episode_stats()
    metrics |= _training_metrics(returns, reward_metrics, train_reward, learned)
    metrics |= _throughput(state, evaluation.env_steps, seconds)
    emitters = search_emitters(scheduler)
    metrics |= {
        "search/objective": float(np.max(objective)),
        "search/true_objective": float(np.max(evaluation.true_objective)),
        "emitter/restarts": float(sum(getattr(e, "restarts", 0) for e in emitters)),
    }
    return metrics


def _archive_metrics(archives: RunArchives, task: str, learned: bool) -> dict[str, float]:
    """``qd/*`` of the true archive and, for a learned reward, ``qd_learned/*``."""
    offset = QD_OFFSETS.get(task, 0.0)
    metrics = {f"qd/{k}": v for k, v in qd_metrics(archives.true, offset).items()}
    if learned:
        deployable = qd_metrics(archives.deployable, offset)
        metrics |= {f"qd_learned/{k}": v for k, v in deployable.items()}
    return metrics


def _training_metrics(
    returns: list[float],
    reward_metrics: dict[str, float],
    train_reward: TrainReward,
    learned: bool,
) -> dict[str, float]:
    """The training episodes' return, the reward model's update and what RL was handed.

    Args:
        returns: true returns of the training episodes that ended this iteration.
        reward_metrics: the reward model's update metrics.
        train_reward: the iteration's training reward, after its rollouts.
        learned: whether the reward is learned (not the true reward).
    """
    metrics = {"rl/train_episode_return": float(np.mean(returns))} if returns else {}
    metrics |= {f"reward/{k}": float(v) for k, v in reward_metrics.items()}
    if learned:
        # what RL is handed per step; the bonus wrapper splits it into learned and bonus
        metrics["reward/train_per_step"] = train_reward.per_step
        metrics.setdefault("reward/learned_per_step", train_reward.per_step)
    metrics |= train_reward.survival.metrics()
    if train_reward.tail is not None:  # r_a where training episodes terminated
        metrics["reward/absorbing"] = train_reward.tail.mean
    return metrics


def _throughput(state: LoopState, steps: int, seconds: float) -> dict[str, float]:
    """``perf/*`` of an iteration of ``steps`` in ``seconds``, after ``LoopState.count``."""
    return {
        "perf/env_steps": float(state.env_steps),
        "perf/sps": steps / seconds,
        "perf/iter_seconds": seconds,
        "perf/elapsed_seconds": state.seconds,
    }


def _checkpoint_due(
    state: LoopState, qd: QDConfig, logging: LoggingConfig, seconds_since_save: float
) -> bool:
    """Whether the iteration just finished ends with a checkpoint.

    Every ``checkpoint_every`` iterations, at the last one (``qd.iterations`` or the
    ``qd.env_steps`` budget), and, when
    ``checkpoint_minutes`` is positive, once that much wall time passed since the last save.
    """
    if state.iteration % logging.checkpoint_every == 0 or finished(
        qd, state.iteration, state.env_steps
    ):
        return True
    minutes = logging.checkpoint_minutes
    return minutes > 0 and seconds_since_save >= 60.0 * minutes


def next_iteration(run: Run, saved: float) -> tuple[dict[str, float], float]:
    """One QD iteration of ``run``, logged, and a checkpoint when one is due.

    Args:
        run: the run.
        saved: ``time.monotonic()`` at the last checkpoint (or the start).

    Returns:
        The iteration's metrics and the time of the last checkpoint.
    """
    with run.own_torch_rng():
        run.state.iteration += 1
        metrics = qd_iteration(run)
        run.tracker.log(metrics, run.state.iteration, run)
        if _checkpoint_due(run.state, run.qd, run.logging, time.monotonic() - saved):
            save_checkpoint(run)
            saved = time.monotonic()
    return metrics, saved


def run_qd(run: Run) -> None:
    """Run iterations until ``qd.iterations`` or the env-step budget, log and checkpoint."""
    progress = run.tracker.progress(run.state.iteration, run.qd.iterations)
    saved = time.monotonic()
    try:
        while not finished(run.qd, run.state.iteration, run.state.env_steps):
            metrics, saved = next_iteration(run, saved)
            progress.update(metrics)
    finally:
        progress.close()
