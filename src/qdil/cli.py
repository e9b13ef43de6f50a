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
from typing import TYPE_CHECKING, Any

# Only the standard library at import time: `qdil --help` and the commands that do not
# train must not pay for torch, Lightning and pyribs (seconds). Each command imports what it
# uses.
if TYPE_CHECKING:
    from jsonargparse import ArgumentParser, Namespace

    from qdil.run import Run

CONFIG_NAME = "config.yaml"
FIT_USAGE = (
    "qdil fit RECIPE.yaml [--section.key VALUE ...]\n"
    "       qdil fit --resume RUN_DIR [--qd.iterations N ...]"
)
FIT_EPILOG = (
    "--resume continues RUN_DIR from its last checkpoint with the recipe in its config.yaml; "
    "a run that stopped before its first checkpoint starts over in place. Only qd.iterations, "
    "env.num_threads, executor.* and logging.* may differ from the checkpoint's recipe. "
    "--reward.help NAME (a registered name or class path) lists a reward model's options."
)


def fit_parser() -> ArgumentParser:
    """The jsonargparse parser of ``qdil fit``."""
    from jsonargparse import ActionConfigFile, ArgumentParser

    from qdil.recipe import recipe

    parser = ArgumentParser(
        prog="qdil fit",
        usage=FIT_USAGE,
        description="Train a QD-IL archive from a recipe: a YAML file with the sections "
        "below; any key can be overridden on the command line.",
        epilog=FIT_EPILOG,
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
    """``--reward gail`` / ``--reward.help gail`` (a registered name) -> the class path."""
    from qdil.rewards import get_reward

    out = list(argv)
    for i, arg in enumerate(out):
        value = None
        if arg in ("--reward", "--reward.help") and i + 1 < len(out):
            value, index = out[i + 1], i + 1
        elif arg.startswith(("--reward=", "--reward.help=")):
            value, index = arg.split("=", 1)[1], i
        if value and "." not in value and not value.startswith("{") and value.isidentifier():
            cls = get_reward(value)
            path = f"{cls.__module__}.{cls.__qualname__}"
            out[index] = path if index == i + 1 else f"{arg.split('=', 1)[0]}={path}"
    return out


def _help_request(argv: list[str]) -> list[str] | None:
    """The first help flag of ``argv`` with its value (``--help``, ``--reward.help gail``)."""
    for i, arg in enumerate(argv):
        if arg in ("-h", "--help"):
            return ["--help"]
        flag = arg.split("=", 1)[0]
        if flag.startswith("--") and flag.endswith(".help"):
            if "=" in arg or i + 1 >= len(argv) or argv[i + 1].startswith("-"):
                return [arg]
            return [arg, argv[i + 1]]
    return None


def fit_help(request: list[str]) -> None:
    """Print ``qdil fit``'s help (or a class's, for ``--reward.help NAME``) and exit 0."""
    from qdil.rewards import discover

    discover()  # registered names and plugin classes, for --reward.help NAME
    try:
        request = _rewrite_reward_flag(request)
    except ValueError as error:
        raise SystemExit(f"qdil fit: error: {request[0]}: {error}") from None
    try:
        fit_parser().parse_args(request)  # a help action prints and exits 0
    except Exception as error:  # an unknown class for --X.help: jsonargparse names it
        raise SystemExit(f"qdil fit: error: {error}") from None
    raise SystemExit(0)  # not reached: help actions exit


def parse_fit(argv: list[str]) -> tuple[Namespace, Path | None, str]:
    """Parse ``qdil fit`` arguments; returns (config, run dir to resume or None, recipe stem).

    The values are checked here, before any run directory exists.

    Raises:
        SystemExit: with a message naming the recipe key on a bad recipe.
    """
    import yaml

    from qdil.recipe import check_values, class_path_problem
    from qdil.rewards import discover

    discover()
    resume_dir = None
    if argv and argv[0] == "--resume":
        if len(argv) < 2:
            raise SystemExit("qdil fit --resume needs a run directory")
        resume_dir = Path(argv[1])
        config_path = resume_dir / CONFIG_NAME
        if not config_path.is_file():
            raise SystemExit(
                f"{resume_dir} is not a qdil run directory (no {CONFIG_NAME}); give a "
                "directory made by `qdil fit RECIPE.yaml`"
            )
        base, overrides, stem = config_path, argv[2:], resume_dir.name
    elif argv and not argv[0].startswith("-"):
        base, overrides, stem = Path(argv[0]), argv[1:], Path(argv[0]).stem
        if not base.exists():
            raise SystemExit(f"recipe {base} not found")
        if base.is_dir():
            examples = sorted(base.glob("*.yaml"))[:1]
            example = f", e.g. {examples[0]}" if examples else ""
            raise SystemExit(f"recipe {base} is a directory; give a recipe file (YAML){example}")
    else:
        raise SystemExit(f"usage: {FIT_USAGE}\n(qdil fit --help lists the recipe's keys)")
    try:
        content = yaml.safe_load(base.read_text()) or {}
    except yaml.YAMLError as error:
        raise SystemExit(f"recipe {base} is not valid YAML: {error}") from None
    except (OSError, UnicodeDecodeError) as error:
        raise SystemExit(f"recipe {base} cannot be read: {error}") from None
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
        # ...but a class in a missing module reads as a type mismatch of the whole union
        problem = class_path_problem(content, overrides)
        raise SystemExit(f"recipe {base}: {problem or error}") from None
    problems = check_values(config)
    if problems:
        raise SystemExit("\n".join(f"recipe {base}: {problem}" for problem in problems))
    return config, resume_dir, stem


def fit(argv: list[str]) -> None:
    """``qdil fit``: build the run, save its resolved recipe, loop, checkpoint."""
    help_request = _help_request(argv)
    if help_request is not None:
        fit_help(help_request)
    import yaml

    from qdil.files import atomic_write, remove_stale_temporaries
    from qdil.qd.checkpoint import (
        CHECKPOINT,
        config_differences,
        load_checkpoint,
        read_checkpoint,
    )
    from qdil.qd.loop import run_qd
    from qdil.rewards.base import NonFiniteRewardError
    from qdil.rl.execution import ExecutorError

    config, resume_dir, stem = parse_fit(argv)
    parser = fit_parser()
    name = config.name or f"{stem}-seed{config.seed}"
    if resume_dir is not None:
        run_dir = resume_dir
    else:
        run_dir = Path(config.logging.root) / name
        if (run_dir / "checkpoints").exists() or (run_dir / "metrics.csv").exists():
            raise SystemExit(
                f"run directory {run_dir} already holds a run; continue it (or, without a "
                f"checkpoint, start it over) with `qdil fit --resume {run_dir}`, or choose "
                "another --name"
            )
    config.name = name
    resolved = parser.dump(config, skip_unset=False)
    for path in remove_stale_temporaries(run_dir, run_dir / CHECKPOINT.parent):
        print(f"removed {path}, left by a killed write", file=sys.stderr)
    state = None
    if resume_dir is not None and (run_dir / CHECKPOINT).exists():
        state = read_checkpoint(run_dir / CHECKPOINT)
        _check_unchanged(state, yaml.safe_load(resolved), run_dir, config_differences)
    elif resume_dir is not None:
        print(
            f"{run_dir} has no checkpoint (the run stopped before its first one); "
            f"starting it over from its {CONFIG_NAME}",
            file=sys.stderr,
        )
    fresh = not run_dir.exists()
    run_dir.mkdir(parents=True, exist_ok=True)
    try:
        atomic_write(run_dir / CONFIG_NAME, lambda file: file.write(resolved.encode()))
        init = parser.instantiate(config)
        run = _build(init, name, run_dir, resolved, resume=state is not None)
    except BaseException:
        if fresh:  # a run that never started leaves no directory behind
            shutil.rmtree(run_dir, ignore_errors=True)
        raise
    if state is not None:
        load_checkpoint(run, state)
        del state  # the checkpoint's bytes are restored into the run; free them
        print(f"resuming {run_dir} at iteration {run.state.iteration}", file=sys.stderr)
    if run.tracker.csv.path.exists():  # rows logged after the checkpoint (all, if none)
        run.tracker.csv.truncate(run.state.iteration)
    try:
        run_qd(run)
    except NonFiniteRewardError as error:
        raise SystemExit(
            f"qdil fit: error: {error}\nAfter the fix, `qdil fit --resume {run_dir}` continues "
            "the run from its last checkpoint (or starts it over if it has none)."
        ) from None
    except ExecutorError as error:  # a worker that could not be replaced: resume later
        raise SystemExit(
            f"qdil fit: error: {error}\n`qdil fit --resume {run_dir}` continues the run from "
            "its last checkpoint (or starts it over if it has none)."
        ) from None
    finally:
        run.vppo.executor.close()
    run.tracker.finish(run)
    print(f"run directory: {run_dir}", file=sys.stderr)


def _check_unchanged(
    state: dict[str, Any], resolved: dict[str, Any], run_dir: Path, differences: Any
) -> None:
    """Refuse a resume whose recipe differs from the one stored with its checkpoint.

    Raises:
        SystemExit: naming the keys that differ and what to do.
    """
    stored = state.get("config")
    if stored is None:  # written before checkpoints stored their recipe
        return
    changed = differences(stored, resolved)
    if changed:
        lines = "\n".join(f"  {line}" for line in changed)
        raise SystemExit(
            f"qdil fit: error: {run_dir / CONFIG_NAME} no longer matches the recipe its "
            f"checkpoint was made with (checkpoint -> now):\n{lines}\n"
            "Restore these keys to resume, or start a new run from the edited file with "
            f"`qdil fit {run_dir / CONFIG_NAME} --name NEW_NAME`. Only qd.iterations, "
            "env.num_threads, executor.* and logging.* may change on resume."
        )


def _build(init: Namespace, name: str, run_dir: Path, resolved: str, *, resume: bool) -> Run:
    """The run of an instantiated recipe (envs, reward model, scheduler, trackers)."""
    import yaml

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
        executor=init.executor,
    )


def rewards(argv: list[str]) -> None:
    """``qdil rewards list``: name, description and source of every reward model."""
    parser = argparse.ArgumentParser(
        prog="qdil rewards",
        description="The reward models qdil knows: built-ins, installed plugins and local "
        "plugin folders ($QDIL_PLUGIN_PATH, default ./plugins).",
    )
    commands = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    commands.add_parser(
        "list",
        help="name, description and source of every registered reward model",
        description="Print the name, one-line description and source of every registered "
        "reward model; a name goes in a recipe's `reward:` or after `--reward`.",
    )
    parser.parse_args(argv)
    from qdil.rewards import list_rewards

    entries = list_rewards()
    width = max(len(e.name) for e in entries)
    for entry in entries:
        print(f"{entry.name:<{width}}  {entry.description}  [{entry.source}]")


def _at_least(low: int) -> Any:
    """An argparse type: an integer of at least ``low``, or an error naming the value."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"must be at least {low}, got {value}")
        return value

    parse.__name__ = "int"  # argparse names the type in its messages
    return parse


def _run_dir(parser: argparse.ArgumentParser, text: str) -> Path:
    """``text`` as a run directory, or a parser error saying what it is instead."""
    path = Path(text)
    if not path.exists():
        parser.error(f"run directory {path} does not exist")
    if not path.is_dir():
        parser.error(
            f"{path} is a file, not a run directory; give a directory made by qdil fit (runs/NAME)"
        )
    if not (path / CONFIG_NAME).is_file():
        parser.error(
            f"{path} is not a qdil run directory (no {CONFIG_NAME}); give a directory made "
            "by qdil fit (runs/NAME)"
        )
    return path


def demos(argv: list[str]) -> None:
    """``qdil demos``: demonstrations from an expert run, their table, or an import."""
    parser = argparse.ArgumentParser(
        prog="qdil demos",
        description="Make demonstrations from a run's true-return archive (the paper's "
        "pipeline: top elites, farthest-point sampling in measure space, one deterministic "
        "episode each), print a demonstration file's table, or import outside data.",
    )
    parser.add_argument("run_dir", nargs="?", metavar="RUN_DIR", help="an expert run directory")
    parser.add_argument("--out", help="output .npz file")
    parser.add_argument("--top", type=_at_least(1), default=500, help="candidate pool: best elites")
    parser.add_argument("--num", type=_at_least(1), default=4, help="demonstrations to pick")
    parser.add_argument("--seed", type=_at_least(0), default=0, help="reset seed of the episodes")
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
        run_dir = _run_dir(parser, args.run_dir)
        from qdil.demos.generate import demos_from_run

        made, qpos, qvel = demos_from_run(run_dir, top=args.top, num=args.num, seed=args.seed)
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
    parser.add_argument("run_dir", metavar="RUN_DIR", help="a run directory made by qdil fit")
    parser.add_argument(
        "--episodes", type=_at_least(1), default=5, help="episodes per elite (PPGA: 50)"
    )
    parser.add_argument("--batch", type=_at_least(1), default=64, help="elites evaluated together")
    parser.add_argument("--seed", type=_at_least(0), default=0, help="reset seed")
    parser.add_argument(
        "--num-threads", type=_at_least(1), default=None, help="physics threads (default: all)"
    )
    args = parser.parse_args(argv)
    run_dir = _run_dir(parser, args.run_dir)
    from qdil.evaluation.rescore import rescore_archive

    _, summary = rescore_archive(
        run_dir, args.episodes, args.batch, args.seed, args.num_threads, progress=True
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
    parser.add_argument(
        "--no-records",
        action="store_true",
        help="do not keep records of the runs in OUT/runs/ (config, curves, final archive "
        "without policies: enough to make the report again when the runs are gone)",
    )
    args = parser.parse_args(argv)
    labels = {}
    for item in args.label:
        path, sep, label = item.rpartition("=")
        if not sep or not path or not label:
            parser.error(f"--label takes RUN_DIR=LABEL, got {item!r}")
        labels[path] = label
    from qdil.evaluation.report import write_report

    made = write_report(
        args.paths,
        args.out,
        labels=labels,
        reference=args.reference,
        records=not args.no_records,
    )
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
    if len(left_out) < len(made.runs):  # at least one run made it into the report
        return
    raise SystemExit(
        "qdil report: error: no run could be included (reasons above); give run directories "
        "made by qdil fit, or folders holding them"
    )


COMMANDS = {"fit": fit, "rewards": rewards, "demos": demos, "eval": evaluate, "report": report}


def _is_user_error(error: BaseException) -> bool:
    """Whether ``error`` is a bad recipe, file or plugin, whose message says how to fix it."""
    if isinstance(error, ValueError | FileNotFoundError | ImportError):  # DemoFormatError too
        return True
    # read from sys.modules: importing the modules here would cost every command torch
    checkpoint = sys.modules.get("qdil.qd.checkpoint")
    if checkpoint is not None and isinstance(error, checkpoint.CheckpointError):
        return True
    executors = sys.modules.get("qdil.rl.execution")  # e.g. an unreachable Ray cluster
    if executors is not None and isinstance(error, executors.ExecutorError):
        return True
    # an incomplete plugin, or a reward model whose values turned NaN: the message names
    # the model and what to check; a traceback into the loop would only hide it
    base = sys.modules.get("qdil.rewards.base")
    return base is not None and isinstance(
        error, base.RewardContractError | base.NonFiniteRewardError
    )


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``qdil`` console script."""
    argv = sys.argv[1:] if argv is None else argv
    parser = argparse.ArgumentParser(
        prog="qdil",
        description=__doc__.split("\n")[0],
        epilog="`qdil COMMAND --help` lists a command's options.",
    )
    parser.add_argument("command", choices=sorted(COMMANDS), help="what to do")
    if not argv or argv[0] in ("-h", "--help"):
        parser.print_help()
        print(__doc__)
        return
    command, rest = argv[0], argv[1:]
    if command not in COMMANDS:
        parser.error(f"unknown command {command!r}; choose from {', '.join(sorted(COMMANDS))}")
    try:
        COMMANDS[command](rest)
    except Exception as error:
        if not _is_user_error(error):
            raise
        # a bad recipe, file or plugin: the message says what and how to fix it
        raise SystemExit(f"qdil {command}: error: {error}") from error


if __name__ == "__main__":
    main()
