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
import shutil
import sys
from pathlib import Path
from typing import TYPE_CHECKING

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

if TYPE_CHECKING:
    from qdil.run import Run

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
    resolved = parser.dump(config, skip_unset=False)
    fresh = not run_dir.exists()
    run_dir.mkdir(parents=True, exist_ok=True)
    try:
        atomic_write(run_dir / CONFIG_NAME, lambda file: file.write(resolved.encode()))
        init = parser.instantiate(config)
        run = _build(init, name, run_dir, resolved, resume=resume_dir is not None)
    except BaseException:
        if fresh:  # a run that never started leaves no directory behind
            shutil.rmtree(run_dir, ignore_errors=True)
        raise
    if resume_dir is not None:
        load_checkpoint(run)
        run.tracker.csv.truncate(run.state.iteration)
        print(f"resuming {run_dir} at iteration {run.state.iteration}", file=sys.stderr)
    run_qd(run)
    run.tracker.finish(run)
    print(f"run directory: {run_dir}", file=sys.stderr)


def _build(init: Namespace, name: str, run_dir: Path, resolved: str, *, resume: bool) -> Run:
    """The run of an instantiated recipe (envs, reward model, scheduler, trackers)."""
    from qdil.run import build_run

    return build_run(
        name=name,
        run_dir=run_dir,
        seed=init.seed,
        env=init.env,
        rl=init.rl,
        reward=init.reward,
        bonus=init.bonus,
        demos=init.demos,
        qd=init.qd,
        logging=init.logging,
        config=yaml.safe_load(resolved),
        resume=resume,
    )


def rewards(argv: list[str]) -> None:
    """``qdil rewards list``: name, description and source of every reward model."""
    from qdil.rewards import list_rewards

    if argv != ["list"]:
        raise SystemExit("usage: qdil rewards list")
    entries = list_rewards()
    width = max(len(e.name) for e in entries)
    for entry in entries:
        print(f"{entry.name:<{width}}  {entry.description}  [{entry.source}]")


def demos(argv: list[str]) -> None:
    """``qdil demos``: demonstrations from an expert run, their table, or an import."""
    parser = argparse.ArgumentParser(
        prog="qdil demos",
        description="Make demonstrations from a run's true-return archive (the paper's "
        "pipeline: top elites, farthest-point sampling in measure space, one deterministic "
        "episode each), print a demonstration file's table, or import outside data.",
    )
    parser.add_argument("run_dir", nargs="?", help="an expert run directory")
    parser.add_argument("--out", help="output .npz file")
    parser.add_argument("--top", type=int, default=500, help="candidate pool: best elites")
    parser.add_argument("--num", type=int, default=4, help="demonstrations to pick")
    parser.add_argument("--seed", type=int, default=0, help="reset seed of the episodes")
    parser.add_argument("--info", metavar="FILE", help="print the table of a demo file")
    parser.add_argument(
        "--import-npz",
        metavar="FILE",
        help="import D4RL-style arrays "
        "(observations, actions, next_observations, optional rewards, "
        "terminals, timeouts) from an .npz; contacts are replayed",
    )
    parser.add_argument("--import-minari", metavar="DATASET", help="import a local Minari dataset")
    parser.add_argument("--task", help="task of imported data, e.g. Walker2d-v5")
    args = parser.parse_args(argv)
    from qdil.demos.io import demo_table, episode_summary, load_demos, save_demos

    if args.info:
        loaded = load_demos(args.info)
        print(demo_table(loaded))
        print("\n".join(episode_summary(loaded)))
        provenance = loaded.metadata
        if "run" in provenance:
            print(
                f"from {provenance['run']} (iteration {provenance.get('run_iteration')}, "
                f"seed {provenance.get('run_seed')}), qdil {provenance.get('qdil_version')}"
            )
        return
    if not args.out:
        parser.error("--out is required to write demonstrations")
    if args.import_npz or args.import_minari:
        from qdil.demos.importing import import_minari, import_npz

        if args.import_minari:
            made = import_minari(args.import_minari, task=args.task)
        else:
            if not args.task:
                parser.error("--task is required with --import-npz")
            made = import_npz(args.import_npz, args.task)
        save_demos(made, args.out)
    else:
        if not args.run_dir:
            parser.error("give a run directory (or --info FILE / --import-npz FILE)")
        from qdil.demos.generate import demos_from_run

        made, qpos, qvel = demos_from_run(args.run_dir, top=args.top, num=args.num, seed=args.seed)
        save_demos(made, args.out, qpos, qvel)
    print(demo_table(made))
    print(f"wrote {args.out}")


def evaluate(argv: list[str]) -> None:
    """``qdil eval``: re-score a run's archive with deterministic episodes on the true reward."""
    parser = argparse.ArgumentParser(
        prog="qdil eval",
        description="Re-evaluate every elite of a run's true-return archive with deterministic "
        "actions; writes corrected_archive.pkl and eval.json into the run directory.",
    )
    parser.add_argument("run_dir")
    parser.add_argument("--episodes", type=int, default=5, help="episodes per elite (PPGA: 50)")
    parser.add_argument("--batch", type=int, default=64, help="elites evaluated together")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--num-threads", type=int, default=None, help="physics threads")
    args = parser.parse_args(argv)
    from qdil.evaluation.rescore import rescore_archive

    _, summary = rescore_archive(
        args.run_dir, args.episodes, args.batch, args.seed, args.num_threads, progress=True
    )
    before, after = summary["training_metrics"], summary["metrics"]
    print(
        f"{summary['elites_evaluated']} elites x {args.episodes} deterministic episodes "
        f"({summary['env_steps']:,} env steps)"
    )
    print("| metric | training archive | corrected |\n|---|---|---|")
    for key in ("qd_score", "qd_score_offset", "coverage", "obj_max", "obj_mean", "num_elites"):
        print(f"| {key} | {before[key]:.6g} | {after[key]:.6g} |")


def report(argv: list[str]) -> None:
    """``qdil report``: the paper's tables, Tukey HSD tests, heatmaps and learning curves."""
    parser = argparse.ArgumentParser(
        prog="qdil report",
        description="Paper-style report of run directories: main table (mean ± std over "
        "seeds), Tukey HSD on the QD-Score, archive heatmaps, learning curves. Runs that are "
        "missing or unfinished are listed, not dropped.",
    )
    parser.add_argument("paths", nargs="+", metavar="RUN_DIR", help="runs or folders of runs")
    parser.add_argument("--out", required=True, help="output folder of the report")
    parser.add_argument(
        "--label",
        action="append",
        default=[],
        metavar="RUN_DIR=LABEL",
        help="method label of one run (repeatable); default: reward model [+ -Bonus]",
    )
    parser.add_argument(
        "--reference",
        metavar="METHOD",
        help="Tukey table: only pairs with this method, as group2 (the paper's layout)",
    )
    args = parser.parse_args(argv)
    labels = {}
    for item in args.label:
        path, sep, label = item.rpartition("=")
        if not sep or not path or not label:
            parser.error(f"--label takes RUN_DIR=LABEL, got {item!r}")
        labels[path] = label
    from qdil.evaluation.report import write_report

    made = write_report(args.paths, args.out, labels=labels, reference=args.reference)
    left_out = [run for run in made.runs if not run.included]
    unfinished = [run for run in made.runs if run.included and run.unfinished]
    print(made.main_table or "no run could be included")
    print(
        f"\n{len(made.runs) - len(left_out)} run(s) included ({len(unfinished)} unfinished), "
        f"{len(left_out)} left out"
    )
    for run in [run for run in made.runs if run.problems or run.notes]:
        print(f"  {run.path}: {run.status}: {'; '.join(run.problems + run.notes)}")
    print(f"report: {Path(args.out) / 'report.md'} (also report.html, tables, figures)")


COMMANDS = {"fit": fit, "rewards": rewards, "demos": demos, "eval": evaluate, "report": report}


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
    from qdil.demos.io import DemoFormatError
    from qdil.qd.checkpoint import CheckpointError

    try:
        COMMANDS[command](rest)
    except (ValueError, FileNotFoundError, CheckpointError, DemoFormatError, ImportError) as error:
        # a bad recipe, file or plugin: the message says what and how to fix it
        raise SystemExit(f"qdil {command}: error: {error}") from error


if __name__ == "__main__":
    main()
