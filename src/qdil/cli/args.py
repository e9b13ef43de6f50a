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
