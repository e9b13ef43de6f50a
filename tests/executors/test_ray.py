"""Ray workers give the local results bit for bit, on one node, on a simulated cluster, and
after a worker is killed; an unreachable cluster is named."""

from __future__ import annotations

import os
import signal

import pytest

ray = pytest.importorskip("ray")

from executor_helpers import make_vppo, run_phases, same_outputs  # noqa: E402

from qdil.executors import ExecutorError, RayExecutor  # noqa: E402


@pytest.fixture
def local(local_outputs) -> list:
    return local_outputs


@pytest.fixture
def one_node():
    ray.init(num_cpus=2, include_dashboard=False)
    yield
    ray.shutdown()


# Each Ray test starts worker processes that import qdil and compile the physics kernels
# (half a minute to a minute per test on 2 cores). The default suite keeps the tests that
# prove the points: a killed worker's work is redone and the results equal local,
# on one node and on a simulated two-node cluster (33 s beside a learning run on
# 2026-11-25; it once stalled on a machine that four other processes kept busy).
@pytest.mark.slow
def test_two_ray_workers_give_the_local_results(one_node, local) -> None:
    executor = RayExecutor(num_workers=2)
    got = run_phases(executor)
    assert same_outputs(local, got)
    assert executor.bytes_sent > 0 and executor.bytes_received > 0
    executor.close()


class _KillsAWorker(RayExecutor):
    """Kills worker 0's process before the second rollout of the first phase."""

    killed = False

    def _run(self, method, calls):
        if method == "collect" and self._history and not self.killed:
            _, pid = ray.get(self.workers[0].where.remote())
            os.kill(pid, signal.SIGKILL)  # its simulations' mid-episode state is lost
            self.killed = True
        return super()._run(method, calls)


def test_a_killed_worker_is_replaced_and_its_work_redone(one_node, local) -> None:
    executor = _KillsAWorker(num_workers=2)
    got = run_phases(executor)
    assert executor.killed
    assert same_outputs(local, got)
    executor.close()


@pytest.mark.slow
def test_a_worker_that_cannot_restart_stops_with_the_resume_command(one_node) -> None:
    executor = _KillsAWorker(num_workers=2, max_restarts=0)
    with pytest.raises(ExecutorError, match="qdil fit --resume"):
        run_phases(executor)
    executor.close()


def test_a_simulated_two_node_cluster_gives_the_local_results(local) -> None:
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    cluster.add_node(num_cpus=1)
    try:
        ray.init(address=cluster.address)
        executor = RayExecutor(num_workers=2)
        got = run_phases(executor)
        nodes = {ray.get(w.where.remote())[0] for w in executor.workers}
        assert len(nodes) == 2  # one worker per node: the shards crossed machines
        assert same_outputs(local, got)
        executor.close()
    finally:
        ray.shutdown()
        cluster.shutdown()


def test_an_unreachable_cluster_is_named() -> None:
    assert not ray.is_initialized()
    with pytest.raises(ExecutorError, match=r"127\.0\.0\.1:1"):
        make_vppo(RayExecutor(address="127.0.0.1:1"))
