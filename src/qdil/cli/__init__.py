"""The ``qdil`` command line: ``qdil COMMAND --help`` for each command (see :data:`EPILOG`)."""

from __future__ import annotations

import argparse
import sys

# Only the standard library at import time: `qdil --help` and the commands that do not
# train must not pay for torch, Lightning and pyribs (seconds). Each command imports what it
# uses.
from qdil.cli.demos import demos
from qdil.cli.export import export
from qdil.cli.fit import build, fit, fit_parser, parse_fit
from qdil.cli.render import render
from qdil.cli.results import evaluate, report
from qdil.cli.rewards import rewards
from qdil.cli.sweep import sweep

__all__ = ["COMMANDS", "build", "fit_parser", "main", "parse_fit"]


EPILOG = """commands:
  qdil fit RECIPE.yaml [--section.key value ...]   train (recipes: jsonargparse dialect)
  qdil fit --resume RUN_DIR [--qd.iterations N]     continue a run from its checkpoint
  qdil sweep RECIPE... --seeds S... [overrides]     every recipe × seed as a run, on Ray Tune
  qdil rewards list                                 registered reward models
  qdil eval RUN_DIR                                 re-score an archive on the true reward
  qdil report RUN_DIR... --out DIR                  paper-style tables, tests and figures
  qdil demos RUN_DIR --out FILE | --info FILE       demonstrations from an expert archive
  qdil render RUN_DIR [--cell I J | --top K]        video of an elite's gait (MP4 or GIF)
  qdil export RUN_DIR --format onnx|torch --out DIR elites as standalone policy files

`qdil COMMAND --help` lists a command's options."""

COMMANDS = {
    "fit": fit,
    "rewards": rewards,
    "demos": demos,
    "eval": evaluate,
    "report": report,
    "render": render,
    "export": export,
    "sweep": sweep,
}


def _is_user_error(error: BaseException) -> bool:
    """Whether ``error`` is a bad recipe, file or plugin, whose message says how to fix it."""
    if isinstance(error, ValueError | FileNotFoundError | ImportError):  # DemoFormatError too
        return True
    # read from sys.modules: importing the modules here would cost every command torch
    checkpoint = sys.modules.get("qdil.qd.checkpoint")
    if checkpoint is not None and isinstance(error, checkpoint.CheckpointError):
        return True
    executors = sys.modules.get("qdil.executors.base")  # e.g. an unreachable Ray cluster
    if executors is not None and isinstance(error, executors.ExecutorError):
        return True
    gl = sys.modules.get("qdil.envs.gl")  # no OpenGL: the message names the packages
    if gl is not None and isinstance(error, gl.GLUnavailableError):
        return True
    # an incomplete plugin, or a reward model whose values turned NaN: the message names
    # the model and what to check; a traceback into the loop would only hide it
    base = sys.modules.get("qdil.rewards.base")
    return base is not None and isinstance(
        error, base.RewardContractError | base.NonFiniteRewardError
    )


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``qdil`` console script."""
    argv = sys.argv[1:] if argv is None else argv
    parser = argparse.ArgumentParser(
        prog="qdil",
        description="quality-diversity imitation learning (WQDIL on PPGA) for MuJoCo locomotion",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("command", choices=sorted(COMMANDS), help="what to do")
    parser.add_argument("-V", "--version", action="store_true", help="print qdil's version")
    if not argv or argv[0] in ("-h", "--help"):
        parser.print_help()
        return
    if argv[0] in ("-V", "--version"):
        from qdil import __version__

        print(f"qdil {__version__}")
        return
    command, rest = argv[0], argv[1:]
    if command not in COMMANDS:
        parser.error(f"unknown command {command!r}; choose from {', '.join(sorted(COMMANDS))}")
    try:
        COMMANDS[command](rest)
    except Exception as error:
        if not _is_user_error(error):
            raise
        # a bad recipe, file or plugin: the message says what and how to fix it
        raise SystemExit(f"qdil {command}: error: {error}") from error
