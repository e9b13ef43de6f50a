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
    listing = commands.add_parser(
        "list",
        help="name, description and source of every registered reward model",
        description="Print the name, one-line description and source of every registered "
        "reward model; a name goes in a recipe's `reward:` or after `--reward`. The list is "
        "read from the models' source; --check imports them as `qdil fit` does.",
    )
    listing.add_argument(
        "--check",
        action="store_true",
        help="import every model (seconds: Lightning and torch), so that a plugin that "
        "fails to import is reported here rather than by `qdil fit`",
    )
    args = parser.parse_args(argv)
    from qdil.rewards.listing import ListedReward, read_listing

    entries = None if args.check else read_listing()
    if entries is None:  # checked, or the source leaves a doubt: import the models
        from qdil.rewards import list_rewards

        entries = [ListedReward(e.name, e.description, e.source) for e in list_rewards()]
    width = max(len(e.name) for e in entries)
    for entry in entries:
        print(f"{entry.name:<{width}}  {entry.description}  [{entry.source}]")
