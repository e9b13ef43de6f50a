"""``qdil rewards list``: the registered reward models."""

from __future__ import annotations

import argparse


def rewards(argv: list[str]) -> None:
    """``qdil rewards list``: name, description and source of every reward model."""
    parser = argparse.ArgumentParser(
        prog="qdil rewards",
        description="The reward models qdil knows: built-ins, installed plugins and local "
        "plugin folders (./plugins and the folders on $QDIL_PLUGIN_PATH).",
    )
    commands = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    commands.add_parser(
        "list",
        help="name, description and source of every registered reward model",
        description="Print the name, one-line description and source of every registered "
        "reward model; a name goes in a recipe's `reward:` or after `--reward`.",
    )
    parser.parse_args(argv)
    from qdil.rewards import list_rewards

    entries = list_rewards()
    width = max(len(e.name) for e in entries)
    for entry in entries:
        print(f"{entry.name:<{width}}  {entry.description}  [{entry.source}]")
