"""Ray workers give the local results bit for bit, on one node, on a simulated cluster, and
after a worker is killed; an unreachable cluster is named, and so is a refused token."""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator

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


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _env_without_ray_auth(home: str, **extra: str) -> dict[str, str]:
    """This process's environment without Ray's variables, HOME replaced, ``extra`` added.

    An earlier local ``ray.init`` of this test process sets RAY_AUTH_MODE=token in
    os.environ, and HOME may hold a ~/.ray/auth_token: neither may leak into the test.
    """
    env = {key: value for key, value in os.environ.items() if not key.startswith("RAY_")}
    return env | {"HOME": home, **extra}


@pytest.fixture
def token_head() -> Iterator[str]:
    """A Ray head node on this machine that requires a token no other process holds.

    It has its own HOME, ports and temp dir (short: Ray's socket paths must stay under
    108 characters), so that neither ``ray.init()`` elsewhere on the machine nor this
    machine's ~/.ray/auth_token meets it. It runs in its own process group, which the
    teardown kills: ``ray stop`` would also stop every other Ray of the machine.
    """
    root = tempfile.mkdtemp(prefix="qdil-ray-")
    os.mkdir(home := os.path.join(root, "home"))
    port = _free_port()
    env = _env_without_ray_auth(home, RAY_AUTH_MODE="token", RAY_AUTH_TOKEN=secrets.token_hex(32))
    command = [sys.executable, "-m", "ray.scripts.scripts", "start", "--head"]  # `ray start`
    command += [f"--port={port}", "--num-cpus=1", "--include-dashboard=false", "--block"]
    command += [f"--dashboard-agent-listen-port={_free_port()}", "--disable-usage-stats"]
    command += [f"--temp-dir={root}/ray"]
    with open(os.path.join(root, "head.log"), "w") as log:
        head = subprocess.Popen(
            command, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
        )
    try:
        _wait_for_port(head, port, os.path.join(root, "head.log"))
        yield f"127.0.0.1:{port}"
    finally:
        with contextlib.suppress(ProcessLookupError):  # the group is gone already
            os.killpg(head.pid, signal.SIGKILL)  # the head and every process it started
        head.wait()
        shutil.rmtree(root, ignore_errors=True)


def _wait_for_port(head: subprocess.Popen, port: int, log: str) -> None:
    """Return once the head's GCS port answers; fail with the head's log if it never does."""
    deadline = time.monotonic() + 60
    while head.poll() is None and time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return
        except OSError:
            time.sleep(0.2)
    with open(log) as text:
        pytest.fail(f"the Ray head did not start:\n{text.read()[-3000:]}")


# RayExecutor's launch path, without workers, in a process of its own: its Ray state and
# environment are the test's, not this test process's
_LAUNCH = """
from qdil.executors import ExecutorError, RayExecutor
try:
    RayExecutor(address={address!r})._launch(None, [])
except ExecutorError as error:
    print(error)
else:
    print("joined")
"""


@pytest.mark.parametrize(
    "auth",
    [
        {},  # what a run with an explicit address sends by default: no token
        {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": "0" * 64},  # another cluster's token
        {"RAY_AUTH_MODE": "token"},  # asks for tokens, holds none: Ray's own early error
    ],
    ids=["no-token-sent", "wrong-token", "no-token-held"],
)
def test_a_refused_token_is_named_with_its_fix(token_head: str, auth: dict, tmp_path) -> None:
    # Ray tries a refused token 20 times, a second apart, before it gives up; 2 tries do here
    env = _env_without_ray_auth(str(tmp_path), RAY_gcs_server_port_wait_time_s="2", **auth)
    launch = [sys.executable, "-c", _LAUNCH.format(address=token_head)]
    done = subprocess.run(launch, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "requires Ray's token authentication" in done.stdout, done.stdout
    assert "RAY_AUTH_TOKEN" in done.stdout and "RAY_AUTH_MODE=disabled" in done.stdout
    assert "cannot reach" not in done.stdout


def test_a_run_without_an_address_never_joins_another_process_local_ray(tmp_path) -> None:
    """Ray's own ``address=None`` joins the cluster named in ``ray_current_cluster`` (left
    by ``ray start`` or a test's cluster, which may stop mid-run); the run starts its own."""
    root = tempfile.mkdtemp(prefix="qdil-ray-")  # short: Ray's socket paths
    try:
        os.mkdir(os.path.join(root, "ray"))
        with open(os.path.join(root, "ray", "ray_current_cluster"), "w") as current:
            current.write(f"127.0.0.1:{_free_port()}")  # a cluster that has gone
        env = _env_without_ray_auth(str(tmp_path), RAY_TMPDIR=root)
        env |= {"RAY_gcs_server_port_wait_time_s": "2", "RAY_DISABLE_USAGE_STATS": "1"}
        launch = [sys.executable, "-c", _LAUNCH.format(address=None)]
        done = subprocess.run(launch, env=env, capture_output=True, text=True, timeout=180)
        assert done.returncode == 0, done.stderr[-3000:]
        assert done.stdout.strip().endswith("joined"), done.stdout
    finally:
        shutil.rmtree(root, ignore_errors=True)


def test_the_address_given_to_ray(monkeypatch) -> None:
    from qdil.executors.ray import ray_address

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    assert ray_address(None) == "local"
    assert ray_address("auto") == "auto" and ray_address("10.0.0.1:6379") == "10.0.0.1:6379"
    monkeypatch.setenv("RAY_ADDRESS", "10.0.0.2:6379")  # a sweep's trial on a cluster
    assert ray_address(None) == "10.0.0.2:6379"
