"""A reward class's registry name read from its source, without importing the class.

Reading records (``qdil report``) needs each run's reward name, not its model: importing a
reward model imports Lightning and torch (seconds). :func:`declared_name` finds the
``@register_reward("name")`` decorator of the class in its module's source, the one place
the name is declared; ``None`` where the source does not say (the caller then imports).
"""

from __future__ import annotations

import ast
import importlib.util
from functools import cache
from pathlib import Path


def declared_name(class_path: str) -> str | None:
    """The name ``@register_reward`` gives the class at ``class_path``, read from its source.

    A class a package re-exports (``qdil.rewards.builtin.GAIL``) is followed to the module
    that defines it.

    Args:
        class_path: ``package.module.Class``.

    Returns:
        The registry name, or None when the module's source cannot be found or the class is
        not decorated there (registered some other way, or not at all).
    """
    for _ in range(4):  # re-exports followed at most this deep
        module, _, qualname = class_path.rpartition(".")
        if not module:
            return None
        origin = _source(module)
        if origin is None:
            return None
        names, imported = _declared(origin)
        if qualname in names:
            return names[qualname]
        if qualname not in imported:
            return None
        class_path = imported[qualname]
    return None


def _source(module: str) -> str | None:
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


@cache
def _declared(path: str) -> tuple[dict[str, str], dict[str, str]]:
    """What the module at ``path`` declares and imports.

    Returns:
        ``{class: registry name}`` of its decorated top-level classes, and
        ``{name: "module.name"}`` of what it imports by absolute ``from`` imports.
    """
    try:
        tree = ast.parse(Path(path).read_text(encoding="utf-8"))
    except (OSError, SyntaxError, UnicodeDecodeError):
        return {}, {}
    names, imported = {}, {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for alias in node.names:
                imported[alias.asname or alias.name] = f"{node.module}.{alias.name}"
        if not isinstance(node, ast.ClassDef):
            continue
        for decorator in node.decorator_list:
            if _is_register_call(decorator):
                names[node.name] = decorator.args[0].value
    return names, imported


def _is_register_call(node: ast.expr) -> bool:
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
