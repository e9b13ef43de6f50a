"""Reading reward models' source without importing them or their packages.

A reward model's module imports Lightning and torch (seconds); its registry name and
description are plain text in its source. :mod:`qdil.rewards.names` and
:mod:`qdil.rewards.listing` read them through these helpers.
"""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path


def module_source(module: str) -> str | None:
    """The ``.py`` file of ``module``, found without importing it or its parent packages.

    ``importlib.util.find_spec`` of a submodule imports its parents, and a reward package's
    ``__init__`` imports its models.
    """
    top, *rest = module.split(".")
    try:
        spec = importlib.util.find_spec(top)
    except (ImportError, ValueError):
        return None
    origin = getattr(spec, "origin", None)
    folders = list(getattr(spec, "submodule_search_locations", None) or [])
    for part in rest:
        found = None
        for folder in folders:
            if (Path(folder) / part / "__init__.py").is_file():
                found = Path(folder) / part / "__init__.py"
                break
            if (Path(folder) / f"{part}.py").is_file():
                found = Path(folder) / f"{part}.py"
                break
        if found is None:
            return None
        origin = str(found)
        folders = [str(found.parent)] if found.name == "__init__.py" else []
    return origin if origin and origin.endswith(".py") else None


def is_register_call(node: ast.expr) -> bool:
    """Whether ``node`` is ``register_reward("name")`` (or ``module.register_reward(...)``)."""
    if not isinstance(node, ast.Call) or len(node.args) != 1 or node.keywords:
        return False
    func = node.func
    called = func.id if isinstance(func, ast.Name) else getattr(func, "attr", None)
    argument = node.args[0]
    return (
        called == "register_reward"
        and isinstance(argument, ast.Constant)
        and isinstance(argument.value, str)
    )
