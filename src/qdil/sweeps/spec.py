"""A sweep spec: a YAML file of stages, each recipes × seeds × a grid of options.

Stages run one after another, so a stage may read what an earlier one made (an expert's
demonstrations). Every stage's trials are planned and checked before the first starts.
Paths in a spec are read from the folder the sweep runs in, as on the command line.
How to write one: docs/guides/sweeps.md.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from qdil.sweeps.trials import Override, Trial, plan_trial

SPEC_KEYS = (
    "name",
    "root",
    "episodes",
    "cpus_per_trial",
    "gpus_per_trial",
    "concurrent",
    "overrides",
)
TOP_KEYS = (*SPEC_KEYS, "report", "stages")
STAGE_KEYS = (*SPEC_KEYS[2:], "name", "recipes", "seeds", "grid", "demos", "report")
DEMOS_KEYS = ("out", "top", "num", "seed")


@dataclass(frozen=True)
class Stage:
    """One stage of a sweep: its trials, and what follows them.

    Attributes:
        name: the stage's name (Tune's experiment: ``<sweep>-<stage>``).
        trials: its trials, checked.
        episodes: re-scoring episodes per elite (0: none).
        cpus: CPUs per trial.
        gpus: GPUs per trial.
        concurrent: trials at once at most (0: as the CPUs and GPUs allow).
        demos: ``qdil demos`` options (``out``, and ``top``, ``num``, ``seed`` if given)
            made from the stage's one trial once it is re-scored; empty: none.
        report: a ``qdil report`` over the stage's trials, written here (None: none).
    """

    name: str
    trials: list[Trial]
    episodes: int = 5
    cpus: int = 1
    gpus: float = 0.0
    concurrent: int = 0
    demos: dict[str, Any] = field(default_factory=dict)
    report: Path | None = None


@dataclass(frozen=True)
class Spec:
    """A whole sweep spec: its name, stages, and the report over all its trials."""

    name: str
    stages: list[Stage]
    report: Path | None = None


def is_spec(path: Path) -> bool:
    """Whether ``path`` is a sweep spec (a YAML mapping with ``stages``), not a recipe.

    Raises:
        ValueError: if the file is not valid YAML, naming the file, line and problem.
    """
    try:
        content = yaml.safe_load(path.read_text())
    except OSError:
        return False  # a missing recipe is named where recipes are read
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        raise ValueError(f"{path} is not valid YAML{where}: {problem}") from None
    return isinstance(content, dict) and "stages" in content


def text(value: Any) -> str:
    """A YAML value as a recipe override on the command line (``true``, ``[64, 64]``)."""
    if isinstance(value, str):
        return value
    return yaml.safe_dump(value, default_flow_style=True).removesuffix("...\n").strip()


def spec_name(path: Path) -> str:
    """The spec's ``name``, or its file's stem."""
    content = yaml.safe_load(path.read_text())
    return str(content.get("name") or path.stem)


def load_spec(
    path: Path,
    extra: list[Override],
    root: Path | None = None,
    name: str | None = None,
    given: dict[str, Any] | None = None,
    only: list[str] | None = None,
) -> Spec:
    """Read, plan and check every stage of the spec at ``path``.

    Args:
        path: the spec file.
        extra: recipe overrides from the command line, applied last to every trial.
        root: the runs folder, if the command line gives one (else the spec's, or ``runs``).
        name: the sweep's name (None: the spec's, or its file's stem).
        given: ``cpus_per_trial``, ``gpus_per_trial`` or ``episodes`` for every stage, over
            the spec's own (the command line's).
        only: the names of the stages to run (None: all); a stage left out makes nothing,
            so the files it would make must exist.

    Raises:
        SystemExit: a malformed spec (naming the file and key), or a trial that fails its
            check (as ``qdil sweep`` checks trials).
    """
    content = yaml.safe_load(path.read_text())
    where = f"qdil sweep: {path}"
    _keys(content, TOP_KEYS, where)
    stages_in = content.get("stages")
    if not isinstance(stages_in, list) or not stages_in:
        raise SystemExit(f"{where}: stages: give a list of stages (name, recipes, seeds)")
    root = root or Path(str(content.get("root", "runs")))
    defaults = {key: content[key] for key in SPEC_KEYS[2:] if key in content}
    made: set[Path] = set()  # demonstrations earlier stages make
    stages, planned = [], {}
    named = [raw.get("name") if isinstance(raw, dict) else None for raw in stages_in]
    missing = sorted(set(only or ()) - set(named))
    if missing:
        raise SystemExit(f"{where}: no stage {missing[0]!r}; its stages: {named}")
    for index, raw in enumerate(stages_in):
        if only is not None and named[index] not in only:
            continue
        _keys(raw, STAGE_KEYS, f"{where}: stages[{index}]")
        stage = _stage(
            {**raw, **(given or {})}, defaults, extra, root, made, f"{where}: stages[{index}]"
        )
        names = [s.name for s in stages]
        if stage.name in names:
            raise SystemExit(f"{where}: stages[{index}]: name {stage.name!r} is used twice")
        for trial in stage.trials:
            earlier, before = planned.get(trial.name, (stage.name, trial))
            if before != trial:
                raise SystemExit(
                    f"{where}: stages {earlier!r} and {stage.name!r} both run {trial.name} "
                    "with other settings"
                )
            planned[trial.name] = (earlier, trial)
        stages.append(stage)
    report = content.get("report")
    name = name or spec_name(path)
    return Spec(name, stages, Path(report) if report else None)


def _keys(mapping: Any, allowed: tuple[str, ...], where: str) -> None:
    if not isinstance(mapping, dict):
        raise SystemExit(f"{where}: give a mapping of {', '.join(allowed)}")
    unknown = sorted(set(mapping) - set(allowed))
    if unknown:
        raise SystemExit(f"{where}: unknown key {unknown[0]!r}; the keys are {', '.join(allowed)}")


def _overrides(value: Any, where: str) -> list[Override]:
    if value is None:
        return []
    if not isinstance(value, dict):
        raise SystemExit(f"{where}: give a mapping of recipe keys to values")
    return [(str(key), text(item)) for key, item in value.items()]


def _stage(
    raw: dict, defaults: dict, extra: list[Override], root: Path, made: set[Path], where: str
) -> Stage:
    """One stage's trials: every recipe × grid point × seed, checked."""
    settings = {**defaults, **raw}
    name, seeds, recipes = raw.get("name"), raw.get("seeds"), raw.get("recipes")
    if not isinstance(name, str) or not name:
        raise SystemExit(f"{where}: name: give the stage a name")
    if not isinstance(seeds, list) or not seeds or not all(isinstance(s, int) for s in seeds):
        raise SystemExit(f"{where}: seeds: give a list of integer seeds")
    if not isinstance(recipes, list) or not recipes:
        raise SystemExit(f"{where}: recipes: give a list of recipe files")
    common = [*_overrides(defaults.get("overrides"), f"{where}: overrides")]
    common += _overrides(raw.get("overrides"), f"{where}: overrides")
    grid = raw.get("grid") or {}
    if not isinstance(grid, dict) or not all(isinstance(v, list) and v for v in grid.values()):
        raise SystemExit(f"{where}: grid: give a mapping of recipe keys to lists of values")
    points = [list(zip(grid, values, strict=True)) for values in itertools.product(*grid.values())]
    trials: list[Trial] = []
    for entry in recipes:
        recipe, own = _recipe(entry, f"{where}: recipes")
        for point in points:
            options = [*common, *own, *((k, text(v)) for k, v in point), *extra]
            for seed in seeds:
                trial, _ = plan_trial(Path(recipe), seed, options, root, pending=made)
                if all(t.name != trial.name for t in trials):
                    trials.append(trial)
    demos = raw.get("demos") or {}
    if demos:
        _keys(demos, DEMOS_KEYS, f"{where}: demos")
        if "out" not in demos or len(trials) != 1:
            raise SystemExit(
                f"{where}: demos: give out (the file to write), in a stage of one trial"
            )
        made.add(Path(demos["out"]).resolve())
    cpus, gpus = settings.get("cpus_per_trial", 1), settings.get("gpus_per_trial", 0.0)
    episodes, concurrent = settings.get("episodes", 5), settings.get("concurrent", 0)
    counts = (cpus - 1, episodes, concurrent)
    if not all(isinstance(n, int) and n >= 0 for n in counts) or not float(gpus) >= 0:
        raise SystemExit(
            f"{where}: cpus_per_trial must be at least 1, and episodes, concurrent and "
            "gpus_per_trial at least 0"
        )
    report = raw.get("report")
    return Stage(
        name, trials, episodes, cpus, float(gpus), concurrent, dict(demos),
        Path(report) if report else None,
    )  # fmt: skip


def _recipe(entry: Any, where: str) -> tuple[str, list[Override]]:
    """A stage's recipe entry: a file, or ``{recipe: FILE, overrides: {...}}``."""
    if isinstance(entry, str):
        return entry, []
    if isinstance(entry, dict) and isinstance(entry.get("recipe"), str):
        _keys(entry, ("recipe", "overrides"), where)
        return entry["recipe"], _overrides(entry.get("overrides"), f"{where}: overrides")
    raise SystemExit(f"{where}: give a recipe file, or a mapping with recipe and overrides")
