"""Reading a recipe file, or a run's ``config.yaml``, with overrides into a checked config.

The parser is jsonargparse's over :func:`qdil.recipe.recipe`; every error names the file
and the key. Only the standard library at import time: jsonargparse, torch and pyribs load
when a recipe is read.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from qdil.files import CONFIG_NAME
from qdil.rewards.names import drop_form_on_switch, resolve_reward_names, rewrite_reward_flag
from qdil.run_names import run_stem

if TYPE_CHECKING:
    from jsonargparse import ArgumentParser, Namespace


class RecipeError(ValueError):
    """A recipe, override or run directory that cannot be read; the message names the key."""


@dataclass(frozen=True)
class LoadedRecipe:
    """A checked recipe.

    Attributes:
        config: the parsed recipe (jsonargparse's namespace, classes not yet built).
        resume_dir: the run directory it continues, or None for a new run.
        stem: the default name of a new run (the recipe's, or what the overrides ran), or
            the run directory's name.
    """

    config: Namespace
    resume_dir: Path | None
    stem: str


_parsers = threading.local()


def recipe_parser(
    parser_class: type[ArgumentParser] | None = None, **kwargs: Any
) -> ArgumentParser:
    """The jsonargparse parser of a recipe: ``--config`` plus every section's keys.

    The plain parser (no arguments) is built once per thread and shared: building it reads
    every section's signature (about 0.1 s), and reading, dumping or building a recipe
    leaves it as it was. Classes named by ``class_path`` are looked up when a recipe is
    read, so rewards registered later are found.

    Args:
        parser_class: the parser class (``qdil fit`` passes one with plain help texts).
        **kwargs: the parser's own options (``prog``, ``usage``, ...).
    """
    if parser_class is None and not kwargs:
        if getattr(_parsers, "plain", None) is None:
            _parsers.plain = _new_parser(None, {})
        return _parsers.plain
    return _new_parser(parser_class, kwargs)


def _new_parser(
    parser_class: type[ArgumentParser] | None, kwargs: dict[str, Any]
) -> ArgumentParser:
    from jsonargparse import ActionConfigFile, ArgumentParser

    from qdil.recipe import recipe

    # no abbreviations: ``--env.num_env 3`` must not set ``env.num_envs``
    parser = (parser_class or ArgumentParser)(
        default_env=False, exit_on_error=False, allow_abbrev=False, **kwargs
    )
    parser.add_argument("--config", action=ActionConfigFile, help="the recipe (YAML)")
    parser.add_function_arguments(recipe, as_positional=False)
    return parser


def load_recipe(
    source: str | Path | Mapping[str, Any],
    overrides: list[str] = (),
    *,
    resume: bool = False,  # type: ignore[assignment]
    stem: str = "experiment",
) -> LoadedRecipe:
    """Read and check a recipe file (or, with ``resume``, a run directory's recipe).

    The values are checked here, before any run directory exists.

    Args:
        source: a recipe file, or with ``resume`` a run directory, or a recipe's mapping
            (what ``yaml.safe_load`` of a file gives: :func:`qdil.recipe_parts.recipe_of`).
        stem: a mapping's name in the default run name (a file's is its own).
        overrides: command-line style overrides (``["--seed", "3", "--reward", "gail"]``).
        resume: ``source`` is a run directory to continue.

    Raises:
        RecipeError: naming the file and the key, for anything that cannot be read or run.
    """
    import yaml

    from qdil.recipe_schema import unknown_keys
    from qdil.upgrades import upgraded

    overrides = list(overrides)
    if resume and isinstance(source, Mapping):
        raise RecipeError("resume continues a run directory: give its path, not a recipe")
    resume_dir = Path(source) if resume else None
    if isinstance(source, Mapping):
        base, content = "built in Python", dict(source)
    elif resume_dir is not None:
        base, stem = resume_dir / CONFIG_NAME, resume_dir.name
        if not base.is_file():
            raise RecipeError(
                f"{resume_dir} is not a qdil run directory (no {CONFIG_NAME}); give a "
                "directory made by `qdil fit RECIPE.yaml`"
            )
    else:
        base = Path(source)
        stem = base.stem
        if not base.exists():
            raise RecipeError(f"recipe {base} not found")
        if base.is_dir():
            examples = sorted(base.glob("*.yaml"))[:1]
            example = f", e.g. {examples[0]}" if examples else ""
            raise RecipeError(f"recipe {base} is a directory; give a recipe file (YAML){example}")
    if not isinstance(source, Mapping):
        try:
            content = yaml.safe_load(base.read_text()) or {}
        except yaml.YAMLError as error:
            raise RecipeError(f"recipe {base} is not valid YAML: {error}") from None
        except (OSError, UnicodeDecodeError) as error:
            raise RecipeError(f"recipe {base} cannot be read: {error}") from None
    if not isinstance(content, dict):
        raise RecipeError(f"recipe {base} must be a mapping of sections (env, reward, rl, qd, ...)")
    content = upgraded(content)  # a run's config.yaml from before a class or key moved
    problems = unknown_keys(content, overrides)  # before torch, pyribs and Lightning load
    if problems:
        raise RecipeError("\n".join(f"recipe {base}: {problem}" for problem in problems))
    from qdil.recipe import check_values, class_path_problem
    from qdil.rewards import discover

    discover()
    try:
        content = drop_form_on_switch(resolve_reward_names(content), overrides)
        overrides = rewrite_reward_flag(overrides)
    except ValueError as error:
        raise RecipeError(f"recipe {base}: reward: {error}") from None
    parser = recipe_parser()
    try:
        config = parser.parse_args(["--config", yaml.safe_dump(content), *overrides])
    except Exception as error:  # jsonargparse's error names the key and the allowed values
        # ...but a class in a missing module reads as a type mismatch of the whole union
        problem = class_path_problem(content, overrides)
        raise RecipeError(f"recipe {base}: {problem or error}") from None
    problems = check_values(config)
    if problems:
        raise RecipeError("\n".join(f"recipe {base}: {problem}" for problem in problems))
    if resume_dir is None:
        stem = run_stem(stem, content, config)
    return LoadedRecipe(config, resume_dir, stem)
