"""The recipe schema of ``qdil fit`` and the checks jsonargparse cannot express.

This module imports the recipe's section types (pyribs, torch, Lightning through the reward
models), so the command line imports it only when ``qdil fit`` needs the schema: ``qdil
--help`` and the other commands do not pay for those imports.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator
from typing import Any

from jsonargparse import Namespace, lazy_instance

from qdil.config import (
    BonusConfig,
    Checked,
    DemoConfig,
    EnvConfig,
    LoggingConfig,
    PolicyConfig,
    QDConfig,
    RewardFactory,
    below_minimum,
)
from qdil.executors import Executor, LocalExecutor
from qdil.qd.vppo import VPPO
from qdil.rewards.base import RewardContractError, RewardModel, check_contract, check_demos
from qdil.seats import GradientEstimator, seat_problem

# The smallest value of every number that has one: the seed's here, each section's in its
# class (qdil.config.Checked.minimums). Checked after parsing so that a message can name the
# key and how to set it (0 iterations would leave a directory with only config.yaml, 0 cells
# an unusable archive, checkpoint_every 0 a ZeroDivisionError after the first iteration; a
# negative checkpoint_minutes would save after every iteration).
SEED_MINIMUM = 0

# Keys whose value is a class (``class_path`` + ``init_args``, or a dotted path).
CLASS_KEYS = ("reward", "rl", "qd.emitter", "qd.scheduler", "executor")


def recipe(
    reward: RewardFactory,
    env: EnvConfig,
    qd: QDConfig,
    policy: PolicyConfig = PolicyConfig(),  # noqa: B008
    rl: GradientEstimator | None = lazy_instance(VPPO),  # noqa: B008 - jsonargparse's lazy default
    bonus: BonusConfig = BonusConfig(),  # noqa: B008
    demos: DemoConfig = DemoConfig(),  # noqa: B008
    logging: LoggingConfig = LoggingConfig(),  # noqa: B008
    executor: Executor = lazy_instance(LocalExecutor),  # noqa: B008
    seed: int = 0,
    name: str | None = None,
) -> None:
    """A qdil recipe: one YAML file describes a run.

    Args:
        reward: reward model: a registered name (``mcwae_wgail``) or ``class_path`` with
            ``init_args``.
        env: the task and its simulations.
        qd: archives, emitter, scheduler and evaluation.
        policy: the policies the archive's solutions are (network widths, observation clip).
        rl: the gradient estimator (``class_path``: ``qdil.qd.VPPO``, ``qdil.qd.ESGradients``
            or any class with the members of ``qdil.seats.GradientEstimator``); ``null``
            for gradient-free emitters (sep-CMA-MAE), which need none.
        bonus: an exploration bonus added to any reward model (``type``: ``single_step``
            or ``ebc``).
        demos: demonstrations for the reward model.
        logging: run directory, checkpoints, W&B.
        executor: who steps the simulations: ``qdil.executors.LocalExecutor`` (this
            process) or ``qdil.executors.RayExecutor`` (Ray workers; ``address``,
            ``num_workers``, ``threads_per_worker``). Results do not depend on it.
        seed: the run's seed; every random stream derives from it.
        name: run name and directory under ``logging.root`` (default: recipe name + seed;
            with ``--reward`` replacing the recipe's model, that model's name in it).
    """


def check_values(config: Namespace) -> list[str]:
    """Problems with the parsed recipe's values, each naming its key and how to fix it.

    Args:
        config: the namespace ``qdil fit``'s parser returned.

    Returns:
        One message per key below its minimum or not applying to the chosen bonus type
        (empty if all is well).
    """
    minimums = {"seed": SEED_MINIMUM} | {
        f"{section.section}.{key}": low
        for section in Checked.__subclasses__()
        for key, low in section.minimums.items()
    }
    problems = [
        problem
        for key, low in minimums.items()
        if (problem := below_minimum(key, config.get(key), low))
    ]
    bonus = config.get("bonus")
    if isinstance(bonus, Namespace):
        problems += BonusConfig(**bonus.as_dict()).problems()
    if config.get("rl") is not None:  # beside an estimator: the search seats
        for key in ("qd.emitter", "qd.scheduler"):
            chosen = config.get(key)
            path = chosen.get("class_path") if isinstance(chosen, Namespace) else None
            problem = isinstance(path, str) and seat_problem(key, _imported(path), search=True)
            if problem:
                problems.append(f"{key}: {problem}")
    reward = config.get("reward")
    path = reward.get("class_path") if isinstance(reward, Namespace) else None
    if isinstance(path, str):
        problem = _contract_problem(path)
        if problem:
            problems.append(f"reward: {problem}")
    return problems


def reward_class(path: str) -> type[RewardModel] | None:
    """The reward model class at ``path`` (``module.Class``, nested classes too), or None."""
    cut = path.rfind(".")
    while cut > 0:
        try:
            obj: Any = importlib.import_module(path[:cut])
        except ImportError:
            cut = path.rfind(".", 0, cut)  # a class nested in a shorter module path
            continue
        for attr in path[cut + 1 :].split("."):
            obj = getattr(obj, attr, None)
        return obj if isinstance(obj, type) and issubclass(obj, RewardModel) else None
    return None


def _contract_problem(path: str) -> str | None:
    """What the reward model class at ``path`` lacks of the contract, or None.

    Checked here so that an incomplete plugin is refused before a run directory exists and
    before the environments are built, not at the first call of the missing method.
    """
    cls = reward_class(path)
    try:
        if cls is not None:
            check_contract(cls)
    except RewardContractError as error:
        return str(error)
    return None


def demos_problem(config: Namespace) -> str | None:
    """Why the recipe's reward model cannot start: it needs demonstrations and has none.

    ``qdil fit`` meets this when its run starts; a sweep asks before any trial starts.
    """
    reward = config.get("reward")
    path = reward.get("class_path") if isinstance(reward, Namespace) else None
    cls = reward_class(path) if isinstance(path, str) else None
    try:
        if cls is not None:
            check_demos(cls, config.get("demos.path"))
    except ValueError as error:
        return str(error)
    return None


def class_path_problem(content: dict[str, Any], overrides: list[str]) -> str | None:
    """Why a class named in the recipe or on the command line cannot be used, if so.

    jsonargparse reports a class path in a missing module, or a class that does not fill
    its seat, as a type mismatch of the whole union (eight lines naming ``Callable[...]``);
    this says which key, and which module or which members are missing.

    Args:
        content: the recipe's YAML content.
        overrides: the command-line arguments after the recipe.

    Returns:
        ``"<key>: <what is wrong>"`` for the first class that cannot be imported or lacks
        members of its seat (:mod:`qdil.seats`), or None.
    """
    search = _has_estimator(content, overrides)
    for key, path in _class_paths(content, overrides):
        problem = _import_problem(path) or seat_problem(key, _imported(path), search)
        if problem is not None:
            return f"{key}: {problem}"
    return None


def _imported(path: str) -> Any:
    """The object at the dotted ``path`` (one that :func:`_import_problem` accepted)."""
    parts = path.split(".")
    for cut in range(len(parts) - 1, 0, -1):
        try:
            obj: Any = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for attr in parts[cut:]:
            obj = getattr(obj, attr)
        return obj
    return None


def _has_estimator(content: dict[str, Any], overrides: list[str]) -> bool:
    """Whether the run has a gradient estimator (``rl`` is not set to null, last word wins)."""
    has = not ("rl" in content and content["rl"] is None)
    for i, arg in enumerate(overrides):
        flag, sep, value = arg.partition("=")
        if flag == "--rl":
            value = value if sep else (overrides[i + 1] if i + 1 < len(overrides) else "")
            has = value.strip().lower() not in ("null", "none")
    return has


def _class_paths(content: dict[str, Any], overrides: list[str]) -> Iterator[tuple[str, str]]:
    """(key, dotted path) of every class the recipe and the overrides name."""

    def walk(value: Any, prefix: str) -> Iterator[tuple[str, str]]:
        if isinstance(value, dict):
            if isinstance(value.get("class_path"), str):
                yield prefix, value["class_path"]
            for name, item in value.items():
                yield from walk(item, f"{prefix}.{name}" if prefix else str(name))
        elif isinstance(value, str) and prefix in CLASS_KEYS and "." in value:
            yield prefix, value

    yield from walk(content, "")
    for i, arg in enumerate(overrides):
        if not arg.startswith("--"):
            continue
        flag, sep, value = arg[2:].partition("=")
        if not sep:
            value = overrides[i + 1] if i + 1 < len(overrides) else ""
        is_class = flag.endswith(".class_path") or flag in CLASS_KEYS
        inline = value.lstrip().startswith(("{", "["))  # a JSON/YAML value, not a path
        if is_class and "." in value and not inline:
            yield flag.removesuffix(".class_path"), value


def _import_problem(path: str) -> str | None:
    """What is wrong with the dotted class path ``path``, or None if it imports."""
    parts = path.split(".")
    if len(parts) < 2 or not all(part.isidentifier() for part in parts):
        return f"{path!r} is not a class path (package.module.Class)"
    for cut in range(len(parts) - 1, 0, -1):
        module_name = ".".join(parts[:cut])
        try:
            obj: Any = importlib.import_module(module_name)
        except ModuleNotFoundError as error:
            if error.name and not module_name.startswith(error.name):
                # the module exists but itself imports something missing
                return f"importing {module_name} (for {path!r}) failed: {error}"
            continue  # maybe a class nested in a shorter module path
        except Exception as error:  # a plugin module that fails at import
            return f"importing {module_name} (for {path!r}) failed: {type(error).__name__}: {error}"
        for depth, attr in enumerate(parts[cut:]):
            if not hasattr(obj, attr):
                if depth == 0 and cut + 1 < len(parts):
                    missing = f"no module named {'.'.join(parts[: cut + 1])!r}"
                else:
                    missing = f"{'.'.join(parts[: cut + depth])} has no {attr!r}"
                return f"cannot import {path!r}: {missing}; check the class path's spelling"
            obj = getattr(obj, attr)
        return None
    return (
        f"cannot import {path!r}: no module named {parts[0]!r}; check the class path's "
        "spelling, or install the package that provides it"
    )
