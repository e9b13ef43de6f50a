"""The trials of a sweep: recipe × seed × options, each an ordinary run directory.

:func:`plan_trials` checks every trial's configuration before anything starts (a bad
override stops the sweep at once, naming its key) and names each trial's run directory as
``qdil fit`` would name it, with a short hash of the options that change what it computes.
A folder that already holds a run of another configuration is never reused.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from qdil.files import CONFIG_NAME
from qdil.qd.checkpoint import RESUMABLE_KEYS, config_differences
from qdil.upgrades import upgraded

Override = tuple[str, str]
"""A recipe override ``(key, value)``: ``--key value`` on the command line."""


@dataclass(frozen=True)
class Trial:
    """One run of a sweep.

    Attributes:
        recipe: the recipe file.
        seed: the run's seed.
        overrides: recipe overrides, in order (later ones win).
        name: its run directory's name (under ``root``).
        root: the runs folder (``logging.root``).
        cwd: the folder the sweep started in, where the trial's relative paths (a
            recipe's ``demos.path``) are read from.
    """

    recipe: Path
    seed: int
    overrides: tuple[Override, ...] = field(default=())
    name: str = ""
    root: Path = Path("runs")
    cwd: Path = Path()

    @property
    def run_dir(self) -> Path:
        """Where the trial's run lives."""
        return self.root / self.name

    def fit_args(self) -> list[str]:
        """``qdil fit`` arguments that start the trial, or continue it where it stopped.

        A folder with a recipe continues (``--resume``: from its checkpoint, or over again
        in place if it has none) with the options a resume may change; otherwise a new run.
        """
        if (self.run_dir / CONFIG_NAME).is_file():
            kept = [pair for pair in self.overrides if resumable(pair[0])]
            return ["--resume", str(self.run_dir), *flat(kept)]
        fresh = [*self.overrides, ("seed", str(self.seed)), ("name", self.name)]
        return [str(self.recipe), *flat(fresh), "--logging.root", str(self.root)]


def resumable(key: str) -> bool:
    """Whether a resume may change recipe key ``key`` (how long, how fast, what is written)."""
    return any(key == name or key.startswith(f"{name}.") for name in RESUMABLE_KEYS)


def flat(overrides: list[Override] | tuple[Override, ...]) -> list[str]:
    """``--key value`` arguments of ``overrides``."""
    return [arg for key, value in overrides for arg in (f"--{key}", value)]


def parse_overrides(args: list[str]) -> list[Override]:
    """``--key value`` and ``--key=value`` arguments as pairs.

    Raises:
        SystemExit: an argument that is not an override, naming it.
    """
    pairs, i = [], 0
    while i < len(args):
        arg = args[i]
        if not arg.startswith("--") or len(arg) == 2:
            raise SystemExit(f"qdil sweep: {arg!r} is not a recipe override (--section.key VALUE)")
        key, equals, value = arg[2:].partition("=")
        if not equals:
            if i + 1 >= len(args):
                raise SystemExit(f"qdil sweep: recipe override --{key} needs a value")
            value, i = args[i + 1], i + 1
        pairs.append((key, value))
        i += 1
    return pairs


def plan_trials(
    recipes: list[Path], seeds: list[int], overrides: list[Override], root: Path
) -> list[Trial]:
    """Every recipe × seed as a trial, each checked as ``qdil fit`` checks a recipe.

    Args:
        recipes: recipe files.
        seeds: seeds of each recipe.
        overrides: options for every trial (``qd.iterations``, ``reward``, ...).
        root: the runs folder.

    Returns:
        The trials, recipe by recipe, seed by seed.

    Raises:
        SystemExit: a bad recipe or override (naming the recipe and key), two trials that
            would share a folder, or a folder holding a run of another configuration.
    """
    from qdil.recipe_load import recipe_parser

    parser, trials, configs = recipe_parser(), [], {}
    for recipe in recipes:
        for seed in seeds:
            trial, resolved = plan_trial(recipe, seed, overrides, root, parser)
            if trial.name in configs and _differences(configs[trial.name], resolved):
                raise SystemExit(
                    f"qdil sweep: {recipe} and an earlier recipe both run as {trial.name} with "
                    "other settings; give the recipes different file names"
                )
            configs[trial.name] = resolved
            trials.append(trial)
    return list(dict((t.name, t) for t in trials).values())


def plan_trial(
    recipe: Path,
    seed: int,
    overrides: list[Override],
    root: Path,
    parser: Any = None,
    pending: set[Path] | None = None,
) -> tuple[Trial, dict]:
    """One trial, checked as ``qdil fit`` checks a recipe; returns it and its configuration.

    ``pending``: demonstration files an earlier stage of the sweep makes (not checked).

    Raises:
        SystemExit: a bad recipe or override, a missing demonstration file, or a folder
            holding a run of another configuration.
    """
    from qdil.recipe import demos_problem
    from qdil.recipe_load import RecipeError, load_recipe, recipe_parser

    parser = parser or recipe_parser()
    recipe, root = recipe.resolve(), root.resolve()
    args = [*flat(overrides), "--seed", str(seed), "--logging.root", str(root)]
    try:
        loaded = load_recipe(recipe, args)
    except RecipeError as error:
        raise SystemExit(str(error)) from None
    config, stem = loaded.config, loaded.stem
    _check_demos(recipe, config, pending or set())
    name = trial_name(stem, seed, overrides)
    trial = Trial(recipe, seed, tuple(overrides), name, root, Path.cwd())
    resolved = yaml.safe_load(parser.dump(_named(config, name), skip_unset=False))
    try:  # the components' own checks (VPPO's minimums, say), as qdil fit meets them
        parser.instantiate(config)
    except (ValueError, TypeError) as error:
        raise SystemExit(f"qdil sweep: recipe {recipe}: {error}") from None
    missing = demos_problem(config)  # the check qdil fit makes when its run starts
    if missing:
        raise SystemExit(f"qdil sweep: recipe {recipe}: {missing}")
    _check_folder(trial, resolved)
    return trial, resolved


def trial_name(stem: str, seed: int, overrides: list[Override] | tuple[Override, ...]) -> str:
    """A trial's run name: ``qdil fit``'s, with a hash of the options that change results.

    For example ``walker_ppga-1a2b3c4d-seed0``.
    """
    options = [pair for pair in overrides if not resumable(pair[0])]
    tag = f"-{_digest(options)}" if options else ""
    return f"{stem}{tag}-seed{seed}"


def _check_demos(recipe: Path, config: Any, pending: set[Path]) -> None:
    """Refuse a demonstration file that does not exist (before any trial starts)."""
    from qdil.demos.io import DemoFormatError, resolve_path

    path = config.demos.path
    if path is not None and Path(path).resolve() not in pending:
        try:
            resolve_path(path)
        except DemoFormatError as error:
            raise SystemExit(f"qdil sweep: recipe {recipe}: demos.path: {error}") from None


def _named(config: Any, name: str) -> Any:
    config.name = name
    return config


def _differences(stored: dict, resolved: dict) -> list[str]:
    return config_differences(stored, resolved, (*RESUMABLE_KEYS, "name", "seed"))


def _check_folder(trial: Trial, resolved: dict) -> None:
    """Refuse a trial whose folder holds a run of another configuration."""
    stored_path = trial.run_dir / CONFIG_NAME
    if not stored_path.is_file():
        return
    stored = upgraded(yaml.safe_load(stored_path.read_text()) or {})
    changed = config_differences(stored, resolved)
    if changed:
        lines = "\n".join(f"  {line}" for line in changed)
        raise SystemExit(
            f"qdil sweep: {trial.run_dir} holds a run of another configuration than the "
            f"sweep's trial {trial.name} (folder -> trial):\n{lines}\nMove or delete the "
            "folder, or give the sweep another --root."
        )


def _digest(options: list[Override]) -> str:
    """Eight hex digits naming a set of options (their order kept: later ones win)."""
    text = "\n".join(f"{key}={value}" for key, value in options)
    return hashlib.sha256(text.encode()).hexdigest()[:8]
