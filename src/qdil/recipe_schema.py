"""The recipe's sections and keys, read from the source of :mod:`qdil.recipe`.

The full parser needs the sections' classes (torch, pyribs, Lightning: seconds). A misspelt
section or key is plain text in the recipe, and the schema is plain text in the source:
:func:`unknown_keys` refuses it before anything heavy loads. Keys of class-valued sections
(``reward``, ``rl``, ``executor``, ``qd.emitter``, ...) are their class's and are left to the
parser.
"""

from __future__ import annotations

import ast
import difflib
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

HERE = Path(__file__).parent
# options of the parser that are no recipe section
PARSER_OPTIONS = ("config", "print_config", "help")


@dataclass(frozen=True)
class Schema:
    """The recipe's sections, and the keys of those that are plain dataclasses.

    Attributes:
        sections: every top-level key (``reward``, ``env``, ..., ``seed``, ``name``).
        keys: ``{section: (key, ...)}`` of the dataclass sections (``env``, ``qd``, ...).
    """

    sections: tuple[str, ...]
    keys: dict[str, tuple[str, ...]]


@cache
def schema() -> Schema | None:
    """The schema as ``qdil/recipe.py`` and ``qdil/config.py`` declare it.

    Returns:
        The schema, or None where their source cannot be read as expected (the full parser
        then checks alone).
    """
    try:
        recipe = _parse(HERE / "recipe.py")
        config = _parse(HERE / "config.py")
    except (OSError, SyntaxError, UnicodeDecodeError):
        return None
    function = next(
        (n for n in recipe.body if isinstance(n, ast.FunctionDef) and n.name == "recipe"), None
    )
    if function is None:
        return None
    classes = {n.name: n for n in config.body if isinstance(n, ast.ClassDef) and _is_dataclass(n)}
    arguments = function.args.posonlyargs + function.args.args + function.args.kwonlyargs
    keys = {}
    for argument in arguments:
        annotation = argument.annotation
        if isinstance(annotation, ast.Name) and annotation.id in classes:
            keys[argument.arg] = _fields(classes[annotation.id])
    return Schema(tuple(argument.arg for argument in arguments), keys)


def unknown_keys(content: dict[str, Any], overrides: list[str]) -> list[str]:
    """Sections and keys of a recipe and its overrides that the recipe does not have.

    Args:
        content: the recipe as read from YAML (after :func:`qdil.upgrades.upgraded`).
        overrides: command-line overrides (``["--env.num_envs", "8"]``).

    Returns:
        One message per unknown name, with the closest known name and the known ones.
    """
    known = schema()
    if known is None:
        return []
    problems = []
    for section, value in content.items():
        problems += _check(known, str(section), "in the recipe")
        if section in known.keys and isinstance(value, dict):
            for key in value:
                problems += _check(known, f"{section}.{key}", "in the recipe")
    for argument in overrides:
        if argument.startswith("--") and len(argument) > 2:
            flag = argument[2:].split("=", 1)[0]
            section = flag.split(".", 1)[0]
            if section not in PARSER_OPTIONS:
                problems += _check(known, ".".join(flag.split(".")[:2]), f"in --{flag}")
    return problems


def _check(known: Schema, name: str, where: str) -> list[str]:
    section, _, key = name.partition(".")
    if section not in known.sections:
        close = difflib.get_close_matches(section, known.sections, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        return [
            f"unknown section {section!r} {where}; {hint}the sections are: "
            + ", ".join(known.sections)
        ]
    if key and section in known.keys and key not in known.keys[section]:
        choices = known.keys[section]
        close = difflib.get_close_matches(key, choices, n=1)
        hint = f"did you mean '{section}.{close[0]}'? " if close else ""
        return [
            f"unknown key '{section}.{key}' {where}; {hint}the keys of {section} are: "
            + ", ".join(choices)
        ]
    return []


def _parse(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"))


def _is_dataclass(node: ast.ClassDef) -> bool:
    for decorator in node.decorator_list:
        target = decorator.func if isinstance(decorator, ast.Call) else decorator
        if getattr(target, "id", getattr(target, "attr", None)) == "dataclass":
            return True
    return False


def _fields(node: ast.ClassDef) -> tuple[str, ...]:
    """The dataclass's fields: its annotated names, ClassVars left out."""
    fields = []
    for statement in node.body:
        if (
            isinstance(statement, ast.AnnAssign)
            and isinstance(statement.target, ast.Name)
            and "ClassVar" not in ast.unparse(statement.annotation)
        ):
            fields.append(statement.target.id)
    return tuple(fields)
