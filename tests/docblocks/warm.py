"""A warm ``qdil`` for the docs test: the heavy libraries imported once, each command a fork.

Every ``qdil`` command of a page would otherwise start a Python that imports torch,
Lightning, pyribs and MuJoCo before it does anything (most of a shortened command's time).
The docs test's subject is what each command does, not how a process starts, so each test
worker keeps one server (``python warm.py serve SOCKET``) that imports those libraries and
nothing of qdil, and the page's ``qdil`` (``python warm.py ARGS...``, standard library only)
hands the server its arguments, working folder, environment and standard streams. The
server forks; the fork takes them over, imports qdil afresh (so plugins, ``PYTHONPATH`` and
the page's files are read as a new process reads them) and runs ``short.py`` as ``python
short.py ARGS...`` would; its exit status comes back to the page's command. The fork lives
in a process group of its own, ended with everything it started when the page's command
ends early (a block's timeout). Without a server the command runs ``short.py`` itself.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import sys
from pathlib import Path

SHORT = Path(__file__).with_name("short.py")
HEAVY = ("numpy", "torch", "lightning", "ribs.archives", "jsonargparse", "mujoco", "yaml")
"""What the server imports: what every ``qdil`` command that works loads first."""
MESSAGE = 1 << 20
"""The largest request (arguments and environment) in bytes."""


def serve(path: str) -> None:
    """Import :data:`HEAVY`, then fork a command for each request on the socket ``path``."""
    import ctypes
    import importlib

    ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG: end with the test worker
    for name in HEAVY:
        importlib.import_module(name)
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # the forks are reaped as they end
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    listener.bind(path)
    listener.listen(16)
    print("ready", flush=True)
    while True:
        connection, _ = listener.accept()
        message, fds, _, _ = socket.recv_fds(connection, MESSAGE, 3)
        if os.fork() == 0:
            listener.close()
            _command(connection, json.loads(message), fds)  # never returns
        for fd in fds:
            os.close(fd)
        connection.close()


def _command(connection: socket.socket, request: dict, fds: list[int]) -> None:
    """In the fork: become the page's command, run it, report its exit status, exit."""
    import atexit
    import importlib
    import runpy
    import threading
    import traceback

    code: int = 1
    try:
        os.setpgid(0, 0)
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        for target, fd in enumerate(fds):
            os.dup2(fd, target)
            os.close(fd)
        os.chdir(request["cwd"])
        before = os.environ.get("PYTHONPATH", "").split(os.pathsep)
        os.environ.clear()
        os.environ.update(request["env"])
        now = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
        sys.path[:] = [*now, *(p for p in sys.path if p not in before and p not in now)]
        importlib.invalidate_caches()
        connection.send(json.dumps({"pid": os.getpid()}).encode())
        threading.Thread(target=_end_with, args=(connection,), daemon=True).start()
        sys.argv = [str(SHORT), *request["argv"]]
        try:
            runpy.run_path(str(SHORT), run_name="__main__")
            code = 0
        except SystemExit as stop:
            code = _exit_status(stop.code)
        except BaseException:
            traceback.print_exc()
        atexit._run_exitfuncs()
    except BaseException:
        traceback.print_exc()
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):
                stream.flush()
        try:
            connection.send(json.dumps({"exit": code}).encode())
        finally:
            os._exit(code)


def _exit_status(code: object) -> int:
    """What the interpreter makes of ``SystemExit(code)``: its status, a message printed."""
    if code is None:
        return 0
    if isinstance(code, int):
        return code
    print(code, file=sys.stderr)
    return 1


def _end_with(connection: socket.socket) -> None:
    """End this command and all it started once the page's command is gone."""
    try:
        while connection.recv(MESSAGE):
            pass
    except OSError:
        pass
    os.killpg(0, signal.SIGKILL)


def run(argv: list[str]) -> int:
    """The page's ``qdil ARGV``: on the warm server where there is one, else ``short.py``."""
    path = os.environ.get("DOCS_WARM")
    client = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    try:
        client.connect(path or "")
    except OSError:
        os.execv(sys.executable, [sys.executable, str(SHORT), *argv])
    request = {"argv": argv, "cwd": os.getcwd(), "env": dict(os.environ)}
    socket.send_fds(client, [json.dumps(request).encode()], [0, 1, 2])
    pid = json.loads(client.recv(MESSAGE))["pid"]

    def forward(number: int, _frame: object) -> None:
        os.killpg(pid, number)

    for number in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(number, forward)
    reply = client.recv(MESSAGE)
    return json.loads(reply)["exit"] if reply else 1  # no reply: the fork was killed


if __name__ == "__main__":
    if sys.argv[1:2] == ["serve"]:
        serve(sys.argv[2])
    else:
        sys.exit(run(sys.argv[1:]))
