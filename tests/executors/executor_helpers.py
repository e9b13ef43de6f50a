"""A small VPPO run through any executor, and an in-process transport for the sharding."""

from __future__ import annotations

import pickle
from typing import Any

import numpy as np
import torch

from qdil.executors.sharded import ShardedExecutor
from qdil.executors.worker import ShardWorker
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from tests.vppo_setup import make_vppo


class _PickledHistoryWorker(ShardWorker):
    def resolve(self, history: list[Any]) -> list[Any]:
        return [pickle.loads(call) for call in history]


class InProcessExecutor(ShardedExecutor):
    """Workers are objects here; calls and results go through pickle, as over a wire."""

    def _launch(self, factory: Any, bounds: list[tuple[int, int]]) -> None:
        self.workers = [
            _PickledHistoryWorker(factory, a, b, self.threads_per_worker) for a, b in bounds
        ]

    def _share(self, value: Any) -> Any:
        return pickle.dumps(value)

    def _run(self, method: str, calls: list[tuple[int, tuple]]) -> list[Any]:
        results = []
        for i, args in calls:
            loaded = [pickle.loads(a) if isinstance(a, bytes) else a for a in args]
            results.append(pickle.loads(pickle.dumps(getattr(self.workers[i], method)(*loaded))))
        return results

    def close(self) -> None:
        self.workers = []


def run_phases(executor: Any, num_envs: int = 12) -> list[Any]:
    """Everything an iteration computes with the executor: phases, evaluations, the stream."""
    algo, scorer = make_vppo(executor, num_envs)
    theta = VectorizedActor.initial_solution(17, 6, (128, 128), 0)
    stats = RunningMeanStd(1, (17,))
    out: list[Any] = []
    phase = algo.compute_jacobian(theta, stats, lambda r: 0.5 * r.rewards + r.obs[..., 0], 1)
    out += [phase.solutions, *(r.obs for r in phase.rollouts), phase.diagnostics]
    learned = scorer.evaluate(
        phase.solutions, phase.stats, 2, 3, lambda r: r.rewards + r.obs[..., 1]
    )
    out += [learned.objective, learned.true_objective, learned.measures, learned.lengths]
    out += [learned.env_steps]
    mean = scorer.evaluate(phase.solutions[:1], phase.stats.select([0]), 8, 4, deterministic=True)
    out += [mean.objective, mean.measures]
    walk = algo.walk(theta, stats, np.array([1.0, 0.5, -0.5]), lambda r: r.rewards, 2)
    out += [walk.solutions, walk.stats.mean, walk.stats.var, walk.diagnostics]
    out += [algo.generator.get_state(), algo.executor.pop_episode_stats()]
    return out


def same_outputs(a: list[Any], b: list[Any]) -> bool:
    """Bit-for-bit equality of :func:`run_phases` outputs."""

    def same(x: Any, y: Any) -> bool:
        if isinstance(x, torch.Tensor):
            return torch.equal(x, y)
        if isinstance(x, np.ndarray):
            return np.array_equal(x, y)
        return x == y

    return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
