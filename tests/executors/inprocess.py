"""An in-process transport for ShardedExecutor: the sharding's numbers without Ray."""

from __future__ import annotations

import pickle
from typing import Any

from qdil.executors.sharded import ShardedExecutor
from qdil.executors.worker import ShardWorker


class InProcessExecutor(ShardedExecutor):
    """Workers are objects here; calls and results go through pickle, as over a wire."""

    def _launch(self, factory: Any, bounds: list[tuple[int, int]]) -> None:
        self.workers = [ShardWorker(factory, a, b, self.threads_per_worker) for a, b in bounds]

    def _share(self, value: Any) -> Any:
        return pickle.dumps(value)

    def _run(self, method: str, calls: list[tuple[int, tuple]]) -> list[Any]:
        results = []
        for i, args in calls:
            loaded = [pickle.loads(a) if isinstance(a, bytes) else a for a in args]
            result = getattr(self.workers[i], method)(*loaded)
            results.append(pickle.loads(pickle.dumps(result)))
        return results

    def close(self) -> None:
        self.workers = []
