"""The ``qdil`` command line.

::

    qdil fit RECIPE.yaml [--section.key value ...]   train (recipes: jsonargparse dialect)
    qdil fit --resume RUN_DIR [--qd.iterations N]     continue a run from its checkpoint
    qdil rewards list                                 registered reward models
    qdil eval RUN_DIR                                 re-score an archive on the true reward
    qdil report RUN_DIR... --out DIR                  paper-style tables, tests and figures
    qdil demos RUN_DIR --out FILE | --info FILE       demonstrations from an expert archive
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import yaml
from jsonargparse import ActionConfigFile, ArgumentParser, Namespace, lazy_instance

from qdil.config import (
    BonusConfig,
    DemoConfig,
    EnvConfig,
    LoggingConfig,
    QDConfig,
    RewardFactory,
)
from qdil.rl.vppo import VPPO

CONFIG_NAME = "config.yaml"


def recipe(
    reward: RewardFactory,
    env: EnvConfig,
    qd: QDConfig,
    rl: VPPO = lazy_instance(VPPO),  # noqa: B008 - jsonargparse's lazy default
    bonus: BonusConfig = BonusConfig(),  # noqa: B008
    demos: DemoConfig = DemoConfig(),  # noqa: B008
    logging: LoggingConfig = LoggingConfig(),  # noqa: B008
    seed: int = 0,
    name: str | None = None,
) -> None:
    """A qdil recipe: one YAML file describes a run.

    Args:
        reward: reward model: a registered name (``mcwae_wgail``) or ``class_path`` with
            ``init_args``.
        env: the task and its simulations.
        qd: archives, emitter, scheduler and evaluation.
        rl: the gradient estimator (``class_path``: ``qdil.rl.VPPO`` or a subclass).
        bonus: the single-step archive exploration bonus.
        demos: demonstrations for the reward model.
        logging: run directory, checkpoints, W&B.
        seed: the run's seed; every random stream derives from it.
        name: run name and directory under ``logging.root`` (default: recipe name + seed).
    """


def fit_parser() -> ArgumentParser:
    """The jsonargparse parser of ``qdil fit``."""
    parser = ArgumentParser(
        prog="qdil fit",
        description="Train a QD-IL archive from a recipe.",
        default_env=False,
        exit_on_error=False,
    )
    parser.add_argument("--config", action=ActionConfigFile, help="the recipe (YAML)")
    parser.add_function_arguments(recipe, as_positional=False)
    return parser


def _resolve_reward_names(config: dict) -> dict:
    """Turn a registered reward name (``reward: gail``) into its class path."""
    from qdil.rewards import get_reward

    reward = config.get("reward")
    if isinstance(reward, str) and "." not in reward:
        cls = get_reward(reward)
        config["reward"] = {"class_path": f"{cls.__module__}.{cls.__qualname__}"}
    elif isinstance(reward, dict) and "." not in str(reward.get("class_path", ".")):
        cls = get_reward(reward["class_path"])
        config["reward"] = {**reward, "class_path": f"{cls.__module__}.{cls.__qualname__}"}
    return config


def _rewrite_reward_flag(argv: list[str]) -> list[str]:
    """``--reward gail`` (a registered name) -> ``--reward <class path>``."""
    from qdil.rewards import get_reward

    out = list(argv)
    for i, arg in enumerate(out):
        value = None
        if arg == "--reward" and i + 1 < len(out):
            value, index = out[i + 1], i + 1
        elif arg.startswith("--reward="):
            value, index = arg.split("=", 1)[1], i
        if value and "." not in value and not value.startswith("{") and value.isidentifier():
            cls = get_reward(value)
            path = f"{cls.__module__}.{cls.__qualname__}"
            out[index] = path if index == i + 1 else f"--reward={path}"
    return out


def parse_fit(argv: list[str]) -> tuple[Namespace, Path | None, str]:
    """Parse ``qdil fit`` arguments; returns (config, run dir to resume or None, recipe stem).

    Raises:
        SystemExit: with a message naming the recipe key on a bad recipe.
    """
    from qdil.rewards import discover

    discover()
    resume_dir = None
    if argv and argv[0] == "--resume":
        if len(argv) < 2:
            raise SystemExit("qdil fit --resume needs a run directory")
        resume_dir = Path(argv[1])
        config_path = resume_dir / CONFIG_NAME
        if not config_path.exists():
            raise SystemExit(f"{resume_dir} is not a qdil run directory (no {CONFIG_NAME})")
        base, overrides, stem = config_path, argv[2:], resume_dir.name
    elif argv and not argv[0].startswith("-"):
        base, overrides, stem = Path(argv[0]), argv[1:], Path(argv[0]).stem
        if not base.exists():
            raise SystemExit(f"recipe {base} not found")
    else:
        raise SystemExit(
            "usage: qdil fit RECIPE.yaml [--key value ...] | qdil fit --resume RUN_DIR"
        )
    try:
        content = yaml.safe_load(base.read_text()) or {}
    except yaml.YAMLError as error:
        raise SystemExit(f"recipe {base} is not valid YAML: {error}") from None
    if not isinstance(content, dict):
        raise SystemExit(f"recipe {base} must be a mapping of sections (env, reward, rl, qd, ...)")
    try:
        content = _resolve_reward_names(content)
        overrides = _rewrite_reward_flag(overrides)
    except ValueError as error:
        raise SystemExit(f"recipe {base}: reward: {error}") from None
    parser = fit_parser()
    try:
        config = parser.parse_args(["--config", yaml.safe_dump(content), *overrides])
    except Exception as error:  # jsonargparse's error names the key and the allowed values
        raise SystemExit(f"recipe {base}: {error}") from None
    return config, resume_dir, stem


def fit(argv: list[str]) -> None:
    """``qdil fit``: build the run, save its resolved recipe, loop, checkpoint."""
    from qdil.qd.checkpoint import atomic_write, load_checkpoint
    from qdil.qd.loop import run_qd
    from qdil.run import build_run

    config, resume_dir, stem = parse_fit(argv)
    parser = fit_parser()
    name = config.name or f"{stem}-seed{config.seed}"
    if resume_dir is not None:
        run_dir = resume_dir
    else:
        run_dir = Path(config.logging.root) / name
        if (run_dir / "checkpoints").exists() or (run_dir / "metrics.csv").exists():
            raise SystemExit(
                f"run directory {run_dir} already holds a run; continue it with "
                f"`qdil fit --resume {run_dir}` or choose another --name"
            )
    config.name = name
    resolved = parser.dump(config, skip_none=False)
    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write(run_dir / CONFIG_NAME, lambda file: file.write(resolved.encode()))
    init = parser.instantiate(config)
    run = build_run(
        name=name, run_dir=run_dir, seed=init.seed, env=init.env, rl=init.rl, reward=init.reward,
        bonus=init.bonus, demos=init.demos, qd=init.qd, logging=init.logging,
        config=yaml.safe_load(resolved),
    )  # fmt: skip
    if resume_dir is not None:
        load_checkpoint(run)
        run.tracker.csv.truncate(run.state.iteration)
        print(f"resuming {run_dir} at iteration {run.state.iteration}", file=sys.stderr)
    run_qd(run)
    run.tracker.finish(run)
    print(f"run directory: {run_dir}", file=sys.stderr)


def rewards(argv: list[str]) -> None:
    """``qdil rewards list``: name, description and source of every reward model."""
    from qdil.rewards import list_rewards

    if argv != ["list"]:
        raise SystemExit("usage: qdil rewards list")
    entries = list_rewards()
    width = max(len(e.name) for e in entries)
    for entry in entries:
        print(f"{entry.name:<{width}}  {entry.description}  [{entry.source}]")


COMMANDS = {"fit": fit, "rewards": rewards}


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``qdil`` console script."""
    argv = sys.argv[1:] if argv is None else argv
    parser = argparse.ArgumentParser(prog="qdil", description=__doc__.split("\n")[0])
    parser.add_argument("command", choices=sorted(COMMANDS), help="what to do")
    if not argv or argv[0] in ("-h", "--help"):
        parser.print_help()
        print(__doc__)
        return
    command, rest = argv[0], argv[1:]
    if command not in COMMANDS:
        parser.error(f"unknown command {command!r}; choose from {', '.join(sorted(COMMANDS))}")
    COMMANDS[command](rest)


if __name__ == "__main__":
    main()
