"""The docs test's warm ``qdil``: a command run in a fork of the server does what the same
command does in a process of its own, and ends with the page's command."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.docblocks.shell import WARM

ROOT = Path(__file__).resolve().parents[2]
SMOKE = ROOT / "recipes" / "smoke" / "walker_true.yaml"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory):
    """A warm server on a socket of its own, ended after the module."""
    path = str(tmp_path_factory.mktemp("warm") / "socket")
    process = subprocess.Popen(
        [sys.executable, str(WARM), "serve", path],
        stdout=subprocess.PIPE,
        start_new_session=True,
    )
    assert process.stdout is not None and process.stdout.readline().strip() == b"ready"
    yield path, process.pid
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()


def qdil(argv: list[str], cwd: Path, warm: str, **env: str) -> subprocess.CompletedProcess:
    """The page's ``qdil ARGV`` as the docs shell runs it, on the server ``warm`` ("": none)."""
    environment = dict(os.environ, DOCS_WARM=warm, QDIL_DOCS_SHORT="1", **env)
    return subprocess.run(
        [sys.executable, str(WARM), *argv],
        cwd=cwd,
        env=environment,
        capture_output=True,
        text=True,
        check=False,
    )


def learned(metrics: Path) -> list[dict[str, str]]:
    """A run's ``metrics.csv`` rows without the timings."""
    import csv

    with metrics.open() as rows:
        table = list(csv.DictReader(rows))
    return [{k: v for k, v in row.items() if not k.startswith("perf/")} for row in table]


def forks(pid: int) -> int:
    """How many forks of the server ``pid`` run now (processes whose parent it is)."""
    count = 0
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # ended while read
            continue
        count += fields[0] != "Z" and int(fields[1]) == pid  # state, then parent pid
    return count


def test_a_command_in_a_fork_does_what_it_does_in_its_own_process(server, tmp_path) -> None:
    path, _ = server
    (tmp_path / "warm").mkdir()
    (tmp_path / "cold").mkdir()
    runs = {}
    for name, socket in (("warm", path), ("cold", "")):
        done = qdil(["fit", str(SMOKE), "--name", "smoke"], tmp_path / name, socket)
        assert done.returncode == 0, done.stderr
        assert "run directory: runs/smoke" in done.stdout + done.stderr
        runs[name] = learned(tmp_path / name / "runs" / "smoke" / "metrics.csv")
    assert runs["warm"] == runs["cold"]  # the same run, bit for bit, timings aside
    for socket in (path, ""):  # a bad command: the same message and exit status
        done = qdil(["fit", "missing.yaml"], tmp_path, socket)
        assert done.returncode == 1 and "recipe missing.yaml not found" in done.stderr


def test_the_fork_ends_with_the_pages_command(server, tmp_path) -> None:
    """A block's timeout kills the page's command; the fork and all it started end too."""
    path, pid = server
    long_run = ["fit", str(SMOKE), "--qd.iterations", "100000", "--name", "long"]
    client = subprocess.Popen(
        [sys.executable, str(WARM), *long_run],
        cwd=tmp_path,
        env=dict(os.environ, DOCS_WARM=path, QDIL_DOCS_SHORT="0"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (tmp_path / "runs" / "long" / "config.yaml").exists():
        time.sleep(0.2)
    assert forks(pid) == 1
    client.kill()
    client.wait()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and forks(pid):
        time.sleep(0.2)
    assert forks(pid) == 0
