"""A small registry of reward models (in the spirit of timm's model registry).

:func:`register_reward` files a class under a name. The first look-up (:func:`get_reward`,
:func:`list_rewards`) runs :func:`discover`: it imports :mod:`qdil.rewards.builtin`, whose
import registers the built-ins, then the entry points of the group ``qdil.rewards``, then the
local plugin folders; importing :mod:`qdil.rewards` alone registers nothing. Rules:
docs/rewards/index.md; plugins: docs/guides/write-a-reward-plugin.md.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
import inspect
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from qdil.rewards.base import RewardModel
from qdil.rewards.listing import (
    BUILT_IN,
    ENTRY_POINT_GROUP,
    LOCAL_PACKAGE,
    plugin_folders,
    plugin_modules,
)

__all__ = [
    "ENTRY_POINT_GROUP",
    "LOCAL_PACKAGE",
    "RegisteredReward",
    "discover",
    "get_reward",
    "list_rewards",
    "plugin_folders",
    "register_reward",
]


@dataclass(frozen=True)
class RegisteredReward:
    """A registry entry: the class and where it came from."""

    name: str
    cls: type[RewardModel]
    source: str

    @property
    def description(self) -> str:
        """The class's one-line description."""
        doc = (self.cls.__doc__ or "").strip().splitlines()
        return self.cls.description or (doc[0] if doc else "")


_REGISTRY: dict[str, RegisteredReward] = {}
_current_source = BUILT_IN
_discovered = False


def register_reward(name: str) -> Callable[[type[RewardModel]], type[RewardModel]]:
    """Class decorator: register a :class:`~qdil.rewards.RewardModel` under ``name``.

    Raises:
        TypeError: if the class is not a ``RewardModel`` subclass.
        ValueError: if another class already has the name.
    """
    if not name.isidentifier() or name != name.lower():
        raise ValueError(f"reward names are lowercase identifiers, got {name!r}")

    def decorator(cls: type[RewardModel]) -> type[RewardModel]:
        if not (inspect.isclass(cls) and issubclass(cls, RewardModel)):
            raise TypeError(f"@register_reward({name!r}) needs a RewardModel subclass, got {cls!r}")
        existing = _REGISTRY.get(name)
        if existing is not None and _qualname(existing.cls) != _qualname(cls):
            raise ValueError(
                f"reward name {name!r} is registered twice: {_qualname(existing.cls)} "
                f"({existing.source}) and {_qualname(cls)} ({_current_source}); rename one"
            )
        cls.name = name
        source = _current_source
        if source == BUILT_IN and not cls.__module__.startswith("qdil."):
            source = f"module {cls.__module__}"  # registered by a plain import
        _REGISTRY[name] = RegisteredReward(name, cls, source)
        return cls

    return decorator


def _qualname(cls: type) -> str:
    return f"{cls.__module__}.{cls.__qualname__}"


def _load_entry_points() -> None:
    global _current_source
    for entry_point in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        dist = entry_point.dist.name if entry_point.dist else "unknown package"
        _current_source = f"entry point {entry_point.name} ({dist})"
        try:
            loaded = entry_point.load()
        except Exception as error:
            raise ImportError(
                f"reward plugin entry point {entry_point.name!r} = {entry_point.value!r} of "
                f"{dist} failed to import: {error}"
            ) from error
        finally:
            _current_source = BUILT_IN
        source = f"entry point {entry_point.name} ({dist})"
        module = loaded.__module__ if inspect.isclass(loaded) else loaded.__name__
        if inspect.isclass(loaded):
            if not issubclass(loaded, RewardModel):
                raise TypeError(
                    f"entry point {entry_point.name!r} of {dist} names {loaded!r}, "
                    "which is not a qdil RewardModel subclass"
                )
            if loaded.name not in _REGISTRY or _REGISTRY[loaded.name].cls is not loaded:
                _current_source = source
                register_reward(loaded.name or entry_point.name)(loaded)
                _current_source = BUILT_IN
        # the package may have been imported (and registered) before discovery ran
        for name, entry in list(_REGISTRY.items()):
            if entry.cls.__module__ == module and entry.source.startswith("module "):
                _REGISTRY[name] = RegisteredReward(name, entry.cls, source)


def _load_folder(folder: Path) -> None:
    global _current_source
    if not folder.is_dir():
        return
    # a namespace for the folder's modules, so that class paths re-import cleanly
    package = sys.modules.get(LOCAL_PACKAGE)
    if package is None:
        spec = importlib.machinery.ModuleSpec(LOCAL_PACKAGE, None, is_package=True)
        package = importlib.util.module_from_spec(spec)
        package.__path__ = []
        sys.modules[LOCAL_PACKAGE] = package
    if str(folder) not in package.__path__:
        package.__path__.append(str(folder))
    for path, is_package in plugin_modules(folder):
        name = f"{LOCAL_PACKAGE}.{path.name if is_package else path.stem}"
        if name in sys.modules:
            continue
        _current_source = f"local plugin {path}"
        try:
            importlib.import_module(name)
        except Exception as error:
            raise ImportError(f"local reward plugin {path} failed to import: {error}") from error
        finally:
            _current_source = BUILT_IN


def discover(force: bool = False) -> None:
    """Import built-ins, entry-point plugins and local plugin folders (once)."""
    global _discovered
    if _discovered and not force:
        return
    importlib.import_module("qdil.rewards.builtin")
    _load_entry_points()
    for folder in plugin_folders():
        _load_folder(folder)
    _discovered = True


def list_rewards() -> list[RegisteredReward]:
    """Every registered reward model, sorted by name."""
    discover()
    return [_REGISTRY[name] for name in sorted(_REGISTRY)]


def get_reward(name: str) -> type[RewardModel]:
    """The class registered under ``name``.

    Raises:
        ValueError: for an unknown name, listing the known ones.
    """
    discover()
    if name not in _REGISTRY:
        known = ", ".join(sorted(_REGISTRY))
        raise ValueError(f"unknown reward model {name!r}; registered: {known}")
    return _REGISTRY[name].cls
