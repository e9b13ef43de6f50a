"""A recipe from Python objects: the sections as dataclasses, the classes as factories.

:func:`recipe_of` turns what a researcher builds in Python (``EnvConfig(...)``, a reward
model class, ``functools.partial(VPPO, rollout_length=64)``) into the mapping a recipe file
holds. The run is then built, recorded and resumed as one from YAML: the same checks, the
same ``config.yaml``, the same bits.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
from collections.abc import Mapping
from typing import Any

from qdil.recipe_load import RecipeError
from qdil.recipe_schema import schema


def recipe_of(**sections: Any) -> dict[str, Any]:
    """The recipe mapping of sections given as Python objects.

    Args:
        **sections: ``reward``, ``env``, ``qd``, ``policy``, ``rl``, ``bonus``, ``demos``,
            ``logging``, ``executor`` (each left out: the recipe's default), and ``seed`` and
            ``name``. A section is a config dataclass (``qdil.config.EnvConfig``), a
            mapping as a recipe file holds it, a class, ``functools.partial(Class,
            key=value)`` for a class with options, a registered reward name, or ``None``
            (``rl=None``: gradient-free emitters).

    Returns:
        The recipe as a mapping (what ``yaml.safe_load`` of a recipe file gives).

    Raises:
        RecipeError: naming the section of an object that a recipe cannot record (an
            instance already built: give its class, or a partial of it, instead).
    """
    known = schema()  # recipe()'s parameters, read from its source
    unknown = sorted(set(sections) - set(known.sections)) if known else []
    if unknown:
        raise RecipeError(
            f"unknown recipe section {unknown[0]!r}; the sections are: " + ", ".join(known.sections)
        )
    return {key: _value(value, key) for key, value in sections.items()}


def _value(value: Any, where: str) -> Any:
    """``value`` as a recipe holds it; ``where`` names it in errors."""
    if value is None or isinstance(value, bool | int | float | str):
        return value
    if inspect.isclass(value):
        return {"class_path": _path(value)}
    if isinstance(value, functools.partial):
        if value.args or not inspect.isclass(value.func):
            raise RecipeError(
                f"{where}: give functools.partial(Class, key=value, ...) with keywords only, "
                f"got {value!r}"
            )
        options = {key: _value(v, f"{where}.{key}") for key, v in value.keywords.items()}
        return {"class_path": _path(value.func), "init_args": options}
    if dataclasses.is_dataclass(value) and not inspect.isclass(value):
        return {
            field.name: _value(getattr(value, field.name), f"{where}.{field.name}")
            for field in dataclasses.fields(value)
        }
    if isinstance(value, Mapping):
        return {str(key): _value(v, f"{where}.{key}") for key, v in value.items()}
    if isinstance(value, list | tuple):
        return [_value(v, f"{where}[{i}]") for i, v in enumerate(value)]
    raise RecipeError(
        f"{where}: a {type(value).__name__} instance cannot be recorded in the run's recipe, "
        "which a resume rebuilds it from; give its class, or functools.partial(Class, "
        "key=value, ...) with its options"
    )


def _path(cls: type) -> str:
    if "<locals>" in cls.__qualname__:
        raise RecipeError(
            f"{cls.__qualname__} is defined inside a function: a recipe names classes by "
            "import path, so define it at a module's top level"
        )
    return f"{cls.__module__}.{cls.__qualname__}"
