"""Write docs/api.md, the reference of qdil's Python API, from the docstrings.

griffe reads the source (nothing is imported) with Google-style docstrings; the page lists
each public object's signature, its docstring and those of its public methods and
properties, in the order of :data:`SECTIONS`::

    python tools/api_reference.py            # writes docs/api.md
    python tools/api_reference.py --check    # exit 1 if docs/api.md is not what it writes

The suite runs the check (tests/test_api_reference.py), so the page follows the code.
"""

from __future__ import annotations

import argparse
import logging
import re
import sys
from pathlib import Path

import griffe

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "api.md"
# (heading, what the section serves, [(the name a user writes, where griffe finds it)])
SECTIONS = [
    (
        "Runs",
        "Build, step, resume and read a run ([guide](guides/python.md)).",
        [
            ("qdil.Experiment", "qdil.experiment.Experiment"),
            ("qdil.load_recipe", "qdil.recipe_load.load_recipe"),
            ("qdil.RecipeError", "qdil.recipe_load.RecipeError"),
            ("qdil.open_run", "qdil.finished_run.open_run"),
            ("qdil.FinishedRun", "qdil.finished_run.FinishedRun"),
        ],
    ),
    (
        "Recipe sections",
        "The dataclasses a recipe's sections fill; each checks its own ranges.",
        [
            (f"qdil.config.{name}", f"qdil.config.{name}")
            for name in (
                *("EnvConfig", "PolicyConfig", "QDConfig", "SearchArchiveConfig"),
                *("DemoConfig", "BonusConfig", "LoggingConfig"),
            )
        ],
    ),
    (
        "QD components",
        "Gradient estimators and emitters for the `rl` and `qd.emitter` seats "
        "([seats](concepts/seats.md)).",
        [
            ("qdil.qd.VPPO", "qdil.qd.vppo.VPPO"),
            ("qdil.qd.ESGradients", "qdil.qd.es_gradients.ESGradients"),
            ("qdil.qd.PPGAEmitter", "qdil.qd.emitter.PPGAEmitter"),
            ("qdil.qd.EvolutionStrategyEmitter", "qdil.qd.es_emitter.EvolutionStrategyEmitter"),
            ("qdil.qd.XNES", "qdil.qd.xnes.XNES"),
        ],
    ),
    (
        "Seats",
        "What the loop calls of each component; a class fits a seat when it has the members.",
        [
            (f"qdil.seats.{name}", f"qdil.seats.{name}")
            for name in (
                *("GradientEstimator", "Emitter", "SearchEmitter", "Scheduler"),
                *("SearchScheduler", "PhaseResult"),
            )
        ],
    ),
    (
        "Reward models",
        "The trainable reward and the reward handed to RL ([reward models](rewards/index.md)).",
        [
            ("qdil.rewards.RewardModel", "qdil.rewards.base.RewardModel"),
            ("qdil.rewards.register_reward", "qdil.rewards.registry.register_reward"),
            ("qdil.rewards.get_reward", "qdil.rewards.registry.get_reward"),
            ("qdil.rewards.list_rewards", "qdil.rewards.registry.list_rewards"),
        ],
    ),
    (
        "Tracking, timing and export",
        "Where metrics go, where an iteration's time goes, and how gaits leave qdil.",
        [
            ("qdil.tracking.Tracker", "qdil.tracking.Tracker"),
            ("qdil.timing.recording", "qdil.timing.recording"),
            ("qdil.timing.section", "qdil.timing.section"),
            ("qdil.timing.timed", "qdil.timing.timed"),
            ("qdil.export.export_policies", "qdil.export.policies.export_policies"),
            ("qdil.export.GaitPolicy", "qdil.export.policy.GaitPolicy"),
            ("qdil.export.ExportedPolicy", "qdil.export.policies.ExportedPolicy"),
        ],
    ),
]
ROLE = re.compile(r":(?:meth|func|class|attr|mod|data|exc):`~?([^`]+)`")


def text(docstring: str) -> str:
    """A docstring's prose as Markdown: Sphinx roles become code, double backticks single."""
    return ROLE.sub(r"`\1`", docstring).replace("``", "`")


def signature(obj: griffe.Object, name: str) -> str:
    """``name(param: type = default, ...) -> returns`` as the source declares it."""
    parts, star = [], False
    for p in obj.parameters:
        if p.name in ("self", "cls"):
            continue
        kind = p.kind.value
        if kind == "keyword-only" and not star:
            parts.append("*")
            star = True
        prefix = {"variadic positional": "*", "variadic keyword": "**"}.get(kind, "")
        star |= kind == "variadic positional"
        part = prefix + p.name + (f": {p.annotation}" if p.annotation else "")
        if p.default is not None and not prefix:
            part += f" = {p.default}"
        parts.append(part)
    returns = f" -> {obj.returns}" if obj.returns and name[0].islower() else ""
    return f"{name}({', '.join(parts)}){returns}"


def sections(obj: griffe.Object) -> list[str]:
    """The docstring as Markdown lines: prose, then Args, Returns, Raises and the like."""
    if obj.docstring is None:
        return []
    lines = []
    for section in obj.docstring.parse(griffe.Parser.google):
        if section.kind.value == "text":
            lines += [text(section.value), ""]
            continue
        title = section.title or section.kind.value.capitalize()
        lines.append(f"**{title}**")
        lines.append("")
        items = section.value if isinstance(section.value, list) else [section.value]
        for item in items:
            name, kind = getattr(item, "name", ""), getattr(item, "annotation", None)
            described = text(getattr(item, "description", str(item))).replace("\n", " ")
            if name:  # a parameter or attribute: `name` (type)
                head = f"`{name}`" + (f" ({kind})" if kind else "")
            else:  # a returned value or a raised error: its type
                head = f"`{kind}`" if kind else ""
            lines.append(f"- {head}: {described}" if head else f"- {described}")
        lines.append("")
    return lines


def public_members(cls: griffe.Class) -> list[griffe.Object]:
    """Methods and properties a user calls, in source order (constructors excepted)."""
    members = [m for n, m in cls.members.items() if not n.startswith("_") and not m.is_alias]
    members = [m for m in members if m.is_function or "property" in m.labels]
    return sorted(members, key=lambda m: m.lineno or 0)


def entry(package: griffe.Module, written: str, path: str) -> list[str]:
    """One object's part of the page."""
    obj = package[path.removeprefix("qdil.")]
    lines = [f"### `{written}`", ""]
    if obj.is_function:
        lines += [f"`{signature(obj, written.rsplit('.', 1)[1])}`", ""]
    elif obj.is_class and "__init__" in obj.members and not obj.members["__init__"].is_alias:
        lines += [f"`{signature(obj.members['__init__'], obj.name)}`", ""]
    lines += sections(obj)
    if obj.is_class:
        for member in public_members(obj):
            if "property" in member.labels:
                head = f"`{obj.name}.{member.name}` (property)"
            else:
                head = f"`{obj.name}.{signature(member, member.name)}`"
            lines += [f"#### {head}", "", *sections(member)]
    return lines


def page() -> str:
    """The whole of docs/api.md."""
    # griffe warns of every parameter a docstring leaves untyped; the page shows what is there
    logging.getLogger("griffe").setLevel(logging.ERROR)
    loader = griffe.GriffeLoader(search_paths=[str(ROOT / "src")])
    package = loader.load("qdil")
    loader.resolve_aliases(implicit=False, external=False)
    lines = [
        "# API reference",
        "",
        "Written from the docstrings by `python tools/api_reference.py`; the suite checks that",
        "it matches the code. How the pieces fit: [the Python guide](guides/python.md),",
        "[the package map](concepts/package.md).",
        "",
    ]
    for heading, about, names in SECTIONS:
        lines += [f"## {heading}", "", about, ""]
        for written, path in names:
            lines += entry(package, written, path)
    return re.sub(r"\n{3,}", "\n\n", "\n".join(lines)).rstrip() + "\n"


def main(argv: list[str] | None = None) -> int:
    """The command line: write the page, or check that it is current."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if the page is stale")
    args = parser.parse_args(argv)
    written = page()
    if args.check:
        if PAGE.read_text() != written:
            print(f"{PAGE} is stale: run python tools/api_reference.py")
            return 1
        return 0
    PAGE.write_text(written)
    print(f"wrote {PAGE} ({written.count(chr(10))} lines)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
