"""The registered reward models listed from their source, without importing them.

``qdil rewards list`` prints each model's name, description and source. Importing the models
(:func:`qdil.rewards.list_rewards`) costs seconds of Lightning and torch; the decorators and
``description`` attributes say the same in the source. Where the source does not say for
certain (a plugin package, a module that registers nothing by decorator, a description
inherited from another model, a name taken twice), :func:`read_listing` says so and the
caller imports the models after all.
"""

from __future__ import annotations

import ast
import importlib.metadata
import os
from dataclasses import dataclass
from pathlib import Path

from qdil.rewards.source import is_register_call, module_source

ENTRY_POINT_GROUP = "qdil.rewards"
LOCAL_PACKAGE = "qdil_local_plugins"
BUILT_IN = "qdil (built-in)"

# Bases whose ``description`` is empty: a model deriving from them alone shows its docstring.
_PLAIN_BASES = {"RewardModel", "AdversarialReward"}


@dataclass(frozen=True)
class ListedReward:
    """One line of ``qdil rewards list``: a model's name, description and source."""

    name: str
    description: str
    source: str


class _Unsure(Exception):
    """The source does not settle what an import would register."""


def read_listing() -> list[ListedReward] | None:
    """Every registered reward model, sorted by name, read from source.

    Returns:
        The entries :func:`qdil.rewards.list_rewards` gives (name, description, source), or
        None where the source leaves a doubt: then only importing the models says.

    Raises:
        FileNotFoundError: for a folder on ``$QDIL_PLUGIN_PATH`` that does not exist.
    """
    try:
        entries = _built_ins() + _entry_points() + _local_plugins()
    except _Unsure:
        return None
    names = [entry.name for entry in entries]
    if len(set(names)) != len(names):
        return None  # a name taken twice: the registry's error says by whom
    return sorted(entries, key=lambda entry: entry.name)


def plugin_folders() -> list[Path]:
    """Local plugin folders: ``./plugins``, then those of ``$QDIL_PLUGIN_PATH``.

    ``$QDIL_PLUGIN_PATH`` is ``os.pathsep``-separated (``:`` on Linux and macOS, ``;`` on
    Windows); its folders are scanned as well as ``./plugins``, which may be absent.

    Raises:
        FileNotFoundError: if a folder on ``$QDIL_PLUGIN_PATH`` does not exist (or is a file):
            a mistyped path would otherwise leave its plugins out without a word.
    """
    folders = [Path.cwd() / "plugins"]
    for entry in os.environ.get("QDIL_PLUGIN_PATH", "").split(os.pathsep):
        if not entry:
            continue
        folder = Path(entry).expanduser().absolute()
        if not folder.is_dir():
            what = "is a file, not a folder" if folder.exists() else "does not exist"
            raise FileNotFoundError(
                f"QDIL_PLUGIN_PATH names the plugin folder {folder}, which {what}; create "
                "it, correct the path, or take it out of QDIL_PLUGIN_PATH (./plugins is "
                "scanned without it)"
            )
        if all(folder.resolve() != known.resolve() for known in folders):
            folders.append(folder)
    return folders


def plugin_modules(folder: Path) -> list[tuple[Path, bool]]:
    """The modules and packages of a plugin folder, in import order, each with ``is_package``."""
    if not folder.is_dir():
        return []
    found = []
    for path in sorted(folder.iterdir()):
        is_module = path.suffix == ".py" and path.stem.isidentifier() and path.stem != "__init__"
        is_package = path.is_dir() and (path / "__init__.py").exists() and path.name.isidentifier()
        if is_module or is_package:
            found.append((path, is_package))
    return found


def _built_ins() -> list[ListedReward]:
    """The decorated models of every module ``qdil.rewards.builtin`` imports from."""
    init = module_source("qdil.rewards.builtin")
    if init is None:
        raise _Unsure("qdil.rewards.builtin has no source")
    modules = {
        node.module
        for node in _parse(Path(init)).body
        if isinstance(node, ast.ImportFrom) and node.module and not node.level
    }
    entries = []
    for module in sorted(modules):
        path = module_source(module)
        if path is None:
            raise _Unsure(f"{module} has no source")
        entries += [ListedReward(n, d, BUILT_IN) for n, d in _decorated(Path(path)).values()]
    return entries


def _entry_points() -> list[ListedReward]:
    """Models of the ``qdil.rewards`` entry points that name a decorated class alone."""
    entries = []
    for entry_point in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        module, _, attribute = entry_point.value.partition(":")
        module, attribute = module.strip(), attribute.strip()
        path = module_source(module)
        if not attribute or path is None:
            raise _Unsure(f"entry point {entry_point.name} names a module, or has no source")
        # every decorated class of the plugin's package must be this one: an import of the
        # package could register others
        package = Path(path).parent if Path(path).name == "__init__.py" else None
        files = sorted(package.rglob("*.py")) if package else [Path(path)]
        decorated = {(f, c): v for f in files for c, v in _decorated(f).items()}
        defining = _defining_file(Path(path), attribute)
        if list(decorated) != [(defining, attribute)]:
            raise _Unsure(f"entry point {entry_point.name}'s package registers other classes")
        dist = entry_point.dist.name if entry_point.dist else "unknown package"
        name, description = decorated[(defining, attribute)]
        entries.append(ListedReward(name, description, f"entry point {entry_point.name} ({dist})"))
    return entries


def _defining_file(path: Path, name: str) -> Path:
    """The file that defines ``name``, following ``from package.module import name``."""
    for _ in range(4):
        tree = _parse(path)
        if any(isinstance(n, ast.ClassDef) and n.name == name for n in tree.body):
            return path
        origin = next(
            (
                module_source(node.module)
                for node in tree.body
                if isinstance(node, ast.ImportFrom) and node.module and not node.level
                for alias in node.names
                if (alias.asname or alias.name) == name and alias.name == name
            ),
            None,
        )
        if origin is None:
            break
        path = Path(origin)
    raise _Unsure(f"{name} is not defined where its entry point says")


def _local_plugins() -> list[ListedReward]:
    """Models of the plugin folders' modules that import no other local plugin."""
    entries = []
    for folder in plugin_folders():
        for path, is_package in plugin_modules(folder):
            if is_package:
                raise _Unsure(f"{path} is a package")
            tree = _parse(path)
            for node in ast.walk(tree):
                imports_local = isinstance(node, ast.ImportFrom) and (
                    node.level or (node.module or "").startswith(LOCAL_PACKAGE)
                )
                if imports_local or (
                    isinstance(node, ast.Import)
                    and any(a.name.startswith(LOCAL_PACKAGE) for a in node.names)
                ):
                    raise _Unsure(f"{path} imports another local plugin")
            decorated = _decorated(path)
            if not decorated:
                raise _Unsure(f"{path} registers nothing by decorator")
            entries += [ListedReward(n, d, f"local plugin {path}") for n, d in decorated.values()]
    return entries


def _decorated(path: Path) -> dict[str, tuple[str, str]]:
    """``{class: (registry name, description)}`` of the module's ``@register_reward`` classes."""
    found = {}
    for node in _parse(path).body:
        if not isinstance(node, ast.ClassDef):
            continue
        calls = [d for d in node.decorator_list if is_register_call(d)]
        if calls:
            found[node.name] = (calls[0].args[0].value, _description(node, path))
    return found


def _description(node: ast.ClassDef, path: Path) -> str:
    """The class's ``description`` or, where it sets none, its docstring's first line."""
    for statement in node.body:
        target = None
        if isinstance(statement, ast.Assign) and len(statement.targets) == 1:
            target = statement.targets[0]
        elif isinstance(statement, ast.AnnAssign):
            target = statement.target
        if isinstance(target, ast.Name) and target.id == "description":
            value = statement.value
            if not (isinstance(value, ast.Constant) and isinstance(value.value, str)):
                raise _Unsure(f"{path}: {node.name}.description is not a plain string")
            if value.value:
                return value.value
    bases = {b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases}
    if not bases <= _PLAIN_BASES:
        raise _Unsure(f"{path}: {node.name} may inherit its description")
    doc = (ast.get_docstring(node) or "").strip().splitlines()
    return doc[0] if doc else ""


def _parse(path: Path) -> ast.Module:
    try:
        return ast.parse(path.read_text(encoding="utf-8"))
    except (OSError, SyntaxError, UnicodeDecodeError) as error:
        raise _Unsure(f"{path} cannot be read: {error}") from None
