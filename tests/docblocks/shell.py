"""A reader's shell for one document: each ``bash`` block runs where the previous one left off.

A reader types a page's blocks into one terminal, so a ``cd`` or an ``export`` in one block
holds in the next. Each block runs in a fresh ``bash`` that starts from the directory and the
exported variables the previous block ended with (``export -p`` replays them), stops at the
first failing command, and fails the test with the block's output.

Two things a reader does are not done here, and the shell says so where a block asks:

- installing: the test runs in the environment the test suite was installed into, which
  holds qdil, its ``dev`` and ``warp`` extras and the two plugins (``.ci/run``); ``python3 -m
  venv`` and ``. .venv/bin/activate`` are then no-ops, ``pip install`` of those is skipped,
  and ``pip install`` of a folder the page made goes into a folder of the test's own (on
  ``PYTHONPATH``), so the test environment stays as it was;
- training at full length: ``qdil`` is ``short.py``'s, under ``QDIL_DOCS_SHORT``.

A page's ``qdil`` runs in a fork of a server that has the heavy libraries imported
(:mod:`warm`), one per test worker, started with the first page.
"""

from __future__ import annotations

import atexit
import os
import shlex
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

from sybil import Example

WARM = Path(__file__).with_name("warm.py")
_server: list[str] = []  # this worker's warm server's socket, once started ("": it failed)

# Defined in every block before the page's commands. Installs named here are what the test
# environment holds already; anything else a page installs is a folder it wrote.
PRELUDE = r"""
set -eo pipefail
qdil() { python "$DOCS_QDIL" "$@"; }
python3() {
    if [ "${1-}" = -m ] && [ "${2-}" = venv ]; then
        echo "docs test: '$*' not run: the test runs in the environment it was installed in"
        mkdir -p "$3/bin" && : > "$3/bin/activate"
    else
        command python3 "$@"
    fi
}
pip() {
    local arg target="" skipped="docs test: 'pip $*' not run: the test environment has it"
    [ "${1-}" = install ] || { echo "$skipped"; return; }
    for arg in "${@:2}"; do
        case "$arg" in
            -e|--editable|.|./plugins/*|.\[*|torch|torch==*) ;;
            -*|*==*) echo "$skipped"; return ;;
            *) target="$arg" ;;
        esac
    done
    [ -n "$target" ] || { echo "$skipped"; return; }
    echo "docs test: 'pip $*' installs $target into $DOCS_SITE instead"
    command pip install -q --no-deps --no-build-isolation --no-index -t "$DOCS_SITE" "$target"
}
"""


class ShellSession:
    """The shell state of one document: working directory and exported variables."""

    def __init__(self, folder: Path, home: Path, state: Path) -> None:
        self.state = state
        state.mkdir(parents=True, exist_ok=True)
        site = state / "site-packages"
        site.mkdir(exist_ok=True)
        env = {k: v for k, v in os.environ.items() if k != "QDIL_PLUGIN_PATH"}
        env.update(
            HOME=str(home),
            # the interpreter running the tests first: `python` and `qdil` are its environment's
            PATH=f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}",
            PYTHONPATH=os.pathsep.join(p for p in (str(site), env.get("PYTHONPATH")) if p),
            DOCS_SITE=str(site),
            DOCS_QDIL=str(WARM),
            DOCS_WARM=warm_server(),
        )
        env.setdefault("QDIL_DOCS_SHORT", "1")
        self.cwd = folder
        self.exports = state / "exports.sh"
        self.exports.write_text(
            "".join(f"export {k}={shlex.quote(v)}\n" for k, v in sorted(env.items()))
        )
        self.cwd_file = state / "cwd"
        self.cwd_file.write_text(str(folder))

    def run(self, commands: str) -> subprocess.CompletedProcess[str]:
        """Run ``commands`` in bash where the last block ended; returns the finished process."""
        script = "\n".join(
            [
                f". {shlex.quote(str(self.exports))}",
                f'cd "$(cat {shlex.quote(str(self.cwd_file))})"',
                PRELUDE,
                # after the page's commands, whether they end the shell or not
                f"trap 'pwd > {shlex.quote(str(self.cwd_file))}; "
                f"export -p > {shlex.quote(str(self.exports))}' EXIT",
                commands,
            ]
        )
        process = subprocess.Popen(
            ["bash", "--noprofile", "--norc", "-c", script],
            env={"PATH": os.environ.get("PATH", "/usr/bin:/bin")},
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,  # its own process group, ended whole below
        )
        try:
            stdout, stderr = process.communicate()
        except BaseException:  # pytest-timeout's alarm, ^C: no training left running behind
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
            raise
        self.cwd = Path(self.cwd_file.read_text().strip())
        return subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)

    def evaluate(self, example: Example) -> str | None:
        """Sybil's evaluator of a ``bash`` block: ``None`` when it succeeds, else why not."""
        done = self.run(example.parsed)
        sys.stdout.write(done.stdout)  # shown by pytest for a failing block, with -s always
        if done.returncode == 0:
            return None
        return (
            f"the block exited with {done.returncode}\n--- stdout (end) ---\n"
            f"{done.stdout[-4000:]}\n--- stderr (end) ---\n{done.stderr[-4000:]}"
        )


def warm_server() -> str:
    """The socket of this worker's warm ``qdil`` server, started on first use ("": none).

    ``QDIL_DOCS_WARM=0`` starts none: each ``qdil`` then starts a process of its own.
    """
    if _server:
        return _server[0]
    if os.environ.get("QDIL_DOCS_WARM") == "0":
        _server.append("")
        return ""
    path = os.path.join(tempfile.mkdtemp(prefix="qdil-warm-"), "socket")
    env = {k: v for k, v in os.environ.items() if k != "QDIL_PLUGIN_PATH"}
    server = subprocess.Popen(
        [sys.executable, str(WARM), "serve", path],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        env=env,
        cwd=os.path.dirname(path),
        start_new_session=True,
    )
    ready = server.stdout.readline().strip() == b"ready" if server.stdout else False
    if not ready:  # each page's qdil then starts a process of its own, as a reader's does
        server.kill()
        path = ""
    else:
        atexit.register(os.killpg, server.pid, signal.SIGKILL)
    _server.append(path)
    return path
