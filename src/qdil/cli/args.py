"""Argument types shared by the commands that read run directories and counts."""

from __future__ import annotations

import argparse
import re
from pathlib import Path
from typing import Any

from qdil.files import CONFIG_NAME


def plain_text(text: str) -> str:
    """Help text from a docstring without its reStructuredText markup.

    ``name`` becomes name, :class:`~qdil.qd.VPPO` becomes VPPO, and a literal-block
    marker ``::`` ending a line becomes ``:``.
    """
    text = re.sub(r":[a-z]+:`~?(?:[\w.]+\.)?([\w]+)`", r"\1", text)
    text = text.replace("``", "")
    return re.sub(r"::(\s*)$", r":\1", text, flags=re.MULTILINE)


def at_least(low: int) -> Any:
    """An argparse type: an integer of at least ``low``, or an error naming the value."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be at least {low}, got {value}")
        return value

    parse.__name__ = "int"  # argparse names the type in its messages
    return parse


def existing_run_dir(parser: argparse.ArgumentParser, text: str) -> Path:
    """``text`` as a run directory, or a parser error saying what it is instead."""
    path = Path(text)
    if not path.exists():
        parser.error(f"run directory {path} does not exist")
    if not path.is_dir():
        parser.error(
            f"{path} is a file, not a run directory; give a directory made by qdil fit (runs/NAME)"
        )
    if not (path / CONFIG_NAME).is_file():
        parser.error(
            f"{path} is not a qdil run directory (no {CONFIG_NAME}); give a directory made "
            "by qdil fit (runs/NAME)"
        )
    return path


def add_elite_choice(parser: argparse.ArgumentParser, top_note: str = "") -> None:
    """``--best | --cell I J | --top K`` and ``--archive``: which elites a command takes.

    ``qdil render`` and ``qdil export`` offer the same choice in the same words.
    """
    pick = parser.add_mutually_exclusive_group()
    pick.add_argument(
        "--best", action="store_true", help="the elite with the best objective (the default)"
    )
    pick.add_argument(
        "--cell",
        nargs="+",
        type=at_least(0),
        metavar="I",
        help="one grid cell, one index per measure: --cell I J for Walker2d",
    )
    pick.add_argument(
        "--top",
        type=at_least(1),
        metavar="K",
        help=f"K elites spread over the measure space (farthest-point sampling from the best)"
        f"{top_note}",
    )
    parser.add_argument(
        "--archive",
        choices=("true", "deployable"),
        default="true",
        help="true: the paper's archive, best policy per cell by true return (default); "
        "deployable: best by the run's own objective",
    )
