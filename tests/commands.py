"""``qdil`` as the tests run it: in this process (:func:`cli`) or as a user's own process
(:func:`qdil`, :func:`start_qdil`), with the environment a user's shell would give it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from qdil.cli import main

ROOT = Path(__file__).resolve().parents[1]
SMOKE = ROOT / "recipes" / "smoke" / "walker_true.yaml"


def user_env(*, threads: bool = True, **extra: str) -> dict[str, str]:
    """This process's environment without the suite's plugin folders, W&B disabled.

    Args:
        threads: keep the suite's ``QDIL_NUM_THREADS`` (False: the threads a user's run has).
        extra: variables to set.
    """
    dropped = {"QDIL_PLUGIN_PATH"} | (set() if threads else {"QDIL_NUM_THREADS"})
    env = {key: value for key, value in os.environ.items() if key not in dropped}
    return env | {"WANDB_MODE": "disabled", **extra}


def qdil(
    *args: str, cwd: Path, env: dict[str, str] | None = None, check: bool = False
) -> subprocess.CompletedProcess:
    """``qdil ARGS`` in a process of its own; ``check`` fails the test with its stderr."""
    done = subprocess.run(
        [sys.executable, "-m", "qdil.cli", *args],
        cwd=cwd,
        env=user_env() if env is None else env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    if check:
        assert done.returncode == 0, done.stderr[-4000:]
    return done


def start_qdil(*args: str, cwd: Path, env: dict[str, str] | None = None) -> subprocess.Popen:
    """``qdil ARGS`` started in a session of its own (killable with its children), silent."""
    return subprocess.Popen(
        [sys.executable, "-m", "qdil.cli", *args],
        cwd=cwd,
        env=user_env() if env is None else env,
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def qdil_here(args: list[str], cwd: Path, **env: str) -> None:
    """``qdil ARGS`` in this process, from ``cwd``, without the suite's plugin folders, with
    the variables ``env`` set: for tests whose subject is not the process (docs/testing.md)."""
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(cwd)
        patch.delenv("QDIL_PLUGIN_PATH", raising=False)
        for key, value in env.items():
            patch.setenv(key, value)
        main(args)


def cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    """(exit code, stdout, stderr) of ``qdil ARGS``, as the console script would give them."""
    try:
        main(args)
        code: int | str | None = 0
    except SystemExit as exit_:
        code = exit_.code
    out, err = capsys.readouterr()
    if isinstance(code, str):  # SystemExit("message"): Python prints it and exits 1
        return 1, out, err + code
    return code or 0, out, err
