"""Rollouts and evaluations on Ray actors, on one machine or a cluster (`qdil[ray]` extra).

Ray does the scheduling, the transport and the fault handling: every worker is an actor
(one training shard each, :class:`~qdil.executors.worker.ShardWorker`) created with
``max_restarts`` and unlimited task retries, so when a worker's process or node dies Ray
starts it again (on any node with a free CPU) and runs the interrupted call again; the
worker replays its phase from references the head keeps, so the retried call returns the
same numbers. A worker that cannot be restarted stops the run with an
:class:`~qdil.executors.base.ExecutorError`; ``qdil fit --resume`` continues it from its
last checkpoint, with Ray or locally. The head sends each call once to Ray's object store
(``ray.put``) and the workers read it from there.
"""

from __future__ import annotations

import importlib
import os
import socket
from typing import Any

from typing_extensions import override

from qdil import numerics
from qdil.executors.base import ExecutorError
from qdil.executors.sharded import ShardedExecutor
from qdil.executors.worker import ShardWorker

INSTALL_HINT = "the Ray executor needs Ray: pip install 'qdil[ray]'"
CONNECT_TIMEOUT_S = 5.0


def import_ray() -> Any:
    """The ``ray`` module, or an ImportError that says how to install it."""
    try:
        return importlib.import_module("ray")
    except ImportError as error:
        raise ImportError(INSTALL_HINT) from error


class RayExecutor(ShardedExecutor):
    """Simulations in shards on Ray actors; PPO, rewards, pyribs and xNES stay on the head.

    Args:
        address: the Ray cluster to join: ``null`` starts a Ray of the run's own on this
            machine unless this process already joined one (``ray.init`` was called) or
            ``RAY_ADDRESS`` names one (never another process's local Ray, which may stop
            mid-run), ``auto`` joins the cluster started on this machine with ``ray start``,
            ``HOST:6379`` joins a cluster's head node from one of its machines,
            ``ray://HOST:10001`` connects through Ray Client.
        num_workers: actors W, one shard of simulations each; each asks Ray for
            ``threads_per_worker`` CPUs.
        threads_per_worker: physics and torch threads of each worker.
        max_restarts: how often Ray may restart each worker after its process or node
            died (``-1``: without limit) before the run stops.
    """

    def __init__(
        self,
        address: str | None = None,
        num_workers: int = 2,
        threads_per_worker: int = 1,
        max_restarts: int = 3,
    ) -> None:
        super().__init__(num_workers, threads_per_worker)
        self.address, self.max_restarts = address, max_restarts
        self.workers: list[Any] = []

    def _launch(self, factory: Any, bounds: list[tuple[int, int]]) -> None:
        ray = import_ray()
        if not ray.is_initialized():
            check_reachable(self.address)
            # a Ray older than its token authentication has no AuthenticationError to catch
            refused = getattr(ray.exceptions, "AuthenticationError", ConnectionError)
            try:
                ray.init(address=ray_address(self.address), log_to_driver=True)
            except (ConnectionError, TimeoutError, refused) as error:
                if _token_refused(error):
                    raise ExecutorError(_token_refused_message(self.address)) from error
                raise ExecutorError(
                    f"cannot reach the Ray cluster at {self.address!r}: {error}. Start it "
                    "(`ray start --head` on the head node, see docs/guides/clusters.md) or set "
                    "executor.init_args.address to its address"
                ) from error
        # every node computes with the head's MKL mode and torch kernels, or refuses to
        numerics_env = numerics.worker_env()
        actor = ray.remote(
            num_cpus=self.threads_per_worker,
            max_restarts=self.max_restarts,
            max_task_retries=-1,  # retried calls replay the phase: the result is the same
            runtime_env={"env_vars": numerics_env},
        )(_RayShardWorker)
        self.workers = [
            actor.remote(factory, start, stop, self.threads_per_worker, numerics_env)
            for start, stop in bounds
        ]

    def _share(self, value: Any) -> Any:
        return import_ray().put(value)

    def _run(self, method: str, calls: list[tuple[int, tuple]]) -> list[Any]:
        ray = import_ray()
        futures = [getattr(self.workers[i], method).remote(*args) for i, args in calls]
        try:
            return ray.get(futures)
        except ray.exceptions.RayActorError as error:
            raise ExecutorError(
                f"a Ray worker died and could not be restarted (max_restarts="
                f"{self.max_restarts}): {error}\nThe run stops here; `qdil fit --resume "
                "RUN_DIR` continues it from its last checkpoint, on the cluster or locally."
            ) from error

    @override
    def close(self) -> None:
        """Stop the workers (the Ray cluster itself keeps running)."""
        ray = import_ray()
        for worker in self.workers:
            ray.kill(worker, no_restart=True)
        self.workers = []


def ray_address(address: str | None) -> str:
    """What ``ray.init`` is given for ``address``: ``None`` means ``RAY_ADDRESS`` or a new Ray.

    Ray itself reads ``None`` as "the cluster last started on this machine" (its
    ``ray_current_cluster`` file, written by ``ray start`` and by test clusters): a run would
    join, and die with, whatever Ray another process left running.
    """
    if address is not None:
        return address
    return os.environ.get("RAY_ADDRESS") or "local"


def check_reachable(address: str | None) -> None:
    """Refuse an address whose port does not answer (``ray.init`` would wait for minutes).

    Raises:
        ExecutorError: naming the address.
    """
    if address in (None, "auto", "local"):
        return  # ray.init finds (or starts) the local cluster, or says it cannot
    host, _, port = address.removeprefix("ray://").rpartition(":")
    try:
        with socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S):
            pass
    except (OSError, ValueError) as error:
        raise ExecutorError(
            f"cannot reach the Ray cluster at {address!r} ({error}); check that its head "
            "node runs (`ray status` there), that the address and port are right (HOST:6379 "
            "for a node of the cluster, ray://HOST:10001 for Ray Client) and that no "
            "firewall blocks them; see docs/guides/clusters.md"
        ) from None


def _token_refused(error: BaseException) -> bool:
    """Whether ``ray.init`` failed on the cluster's token authentication, not on the network.

    Ray raises its ``AuthenticationError`` at once when this process asks for token
    authentication but finds no token. A token that the cluster refuses (none sent, or a
    different one) surfaces only after Ray's retries, as a ``ConnectionError`` whose cause
    holds the last GCS error as formatted text: hence the search of the chain's messages.

    Args:
        error: what ``ray.init`` raised.

    Returns:
        True if an exception of the chain is, or quotes, Ray's authentication error.
    """
    seen: set[int] = set()
    link: BaseException | None = error
    while link is not None and id(link) not in seen:
        seen.add(id(link))
        if type(link).__name__ == "AuthenticationError" or "InvalidAuthToken" in str(link):
            return True
        link = link.__cause__ or link.__context__
    return False


def _token_refused_message(address: str | None) -> str:
    """The error of a cluster that refused this process's token: why, and the fixes.

    Args:
        address: the Ray address given to the executor.

    Returns:
        The message of the :class:`~qdil.executors.base.ExecutorError`.
    """
    mode = os.environ.get("RAY_AUTH_MODE")
    if mode == "token":
        why = "the token this process sent is missing or not the cluster's"
    else:
        # the usual case: `ray start --head` turns tokens on by itself where
        # ~/.ray/auth_token exists, but a process joining an explicit address sends its
        # token only when told to, even from a machine that holds the right file
        why = (
            f"this process sent no token (RAY_AUTH_MODE is {mode or 'unset'} here; Ray "
            "sends one to an explicit address only with RAY_AUTH_MODE=token)"
        )
    return (
        f"the Ray cluster at {address!r} answered but refused this process: it requires "
        f"Ray's token authentication and {why}. Ray reads the token from RAY_AUTH_TOKEN, "
        "else from the file that RAY_AUTH_TOKEN_PATH names, else from ~/.ray/auth_token. "
        "Print the cluster's token with `ray get-auth-token` on the head node, then here "
        "`export RAY_AUTH_MODE=token RAY_AUTH_TOKEN=<that token>` (or copy the head's "
        "~/.ray/auth_token to this machine and export RAY_AUTH_MODE=token); on a trusted "
        "network, start the head node with RAY_AUTH_MODE=disabled instead. See "
        "docs/guides/clusters.md#authentication"
    )


class _RayShardWorker(ShardWorker):
    """A :class:`ShardWorker` that fetches the phase's earlier calls from the object store."""

    def resolve(self, history: list[Any]) -> list[Any]:
        return import_ray().get(history)

    def where(self) -> tuple[str, int]:
        """The worker's node id and process id (for tests and for finding its logs)."""
        return import_ray().get_runtime_context().get_node_id(), os.getpid()
