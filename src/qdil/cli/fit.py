"""``qdil fit``: parse a recipe (or a run to resume), build the run, loop, checkpoint."""

from __future__ import annotations

import contextlib
import shutil
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from qdil.cli.args import plain_text
from qdil.files import CONFIG_NAME
from qdil.rewards.names import rewrite_reward_flag

# Only the standard library at import time (see qdil.cli): torch, Lightning and pyribs load
# inside the functions that use them.
if TYPE_CHECKING:
    from jsonargparse import ArgumentParser, Namespace

    from qdil.run import Run
    from qdil.tracking import Tracker

FIT_USAGE = (
    "qdil fit RECIPE.yaml [--section.key VALUE ...]\n"
    "       qdil fit --resume RUN_DIR [--qd.iterations N] [--qd.env_steps N ...]"
)
FIT_EPILOG = (
    "--resume continues RUN_DIR from its last checkpoint with the recipe in its config.yaml; "
    "a run that stopped before its first checkpoint starts over in place. Only qd.iterations, "
    "qd.env_steps, env.num_threads, executor.* and logging.* may differ from the checkpoint's "
    "recipe. "
    "--reward.help NAME (a registered name, class name or class path) lists a reward "
    "model's options."
)


def fit_parser() -> ArgumentParser:
    """The jsonargparse parser of ``qdil fit``: the recipe's, with plain help texts."""
    from jsonargparse import ArgumentParser, DefaultHelpFormatter

    from qdil.recipe_load import recipe_parser

    class PlainHelpFormatter(DefaultHelpFormatter):
        """jsonargparse's help, its docstring-made texts without reStructuredText markup."""

        def _expand_help(self, action: Any) -> str:
            return plain_text(super()._expand_help(action))

        def _format_text(self, text: str) -> str:  # group descriptions
            return super()._format_text(plain_text(text))

        def start_section(self, heading: str | None) -> None:  # group titles
            super().start_section(heading and plain_text(heading))

    class PlainArgumentParser(ArgumentParser):
        """Keeps the plain help in the parsers that ``--reward.help NAME`` builds from it."""

        def __init__(self, *args: Any, **kwargs: Any) -> None:
            kwargs.setdefault("formatter_class", PlainHelpFormatter)
            super().__init__(*args, **kwargs)

    return recipe_parser(
        PlainArgumentParser,
        prog="qdil fit",
        usage=FIT_USAGE,
        description="Train a QD-IL archive from a recipe: a YAML file with the sections "
        "below; any key can be overridden on the command line.",
        epilog=FIT_EPILOG,
    )


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
        request = rewrite_reward_flag(request)
    except ValueError as error:
        raise SystemExit(f"qdil fit: error: {request[0]}: {error}") from None
    try:
        fit_parser().parse_args(request)  # a help action prints and exits 0
    except Exception as error:  # an unknown class for --X.help: jsonargparse names it
        raise SystemExit(f"qdil fit: error: {error}") from None
    raise SystemExit(0)  # not reached: help actions exit


def parse_fit(argv: list[str]) -> tuple[Namespace, Path | None, str]:
    """Parse ``qdil fit`` arguments; returns (config, run dir to resume or None, name stem).

    :func:`qdil.recipe_load.load_recipe` on the command line's recipe or ``--resume`` run.

    Raises:
        SystemExit: with a message naming the recipe key on a bad recipe.
    """
    from qdil.recipe_load import RecipeError, load_recipe

    if argv and argv[0] == "--resume":
        if len(argv) < 2:
            raise SystemExit("qdil fit --resume needs a run directory")
        source, overrides, resume = argv[1], argv[2:], True
    elif argv and not argv[0].startswith("-"):
        source, overrides, resume = argv[0], argv[1:], False
    else:
        raise SystemExit(f"usage: {FIT_USAGE}\n(qdil fit --help lists the recipe's keys)")
    try:
        loaded = load_recipe(source, overrides, resume=resume)
    except RecipeError as error:
        raise SystemExit(str(error)) from None
    return loaded.config, loaded.resume_dir, loaded.stem


def fit(argv: list[str]) -> None:
    """``qdil fit``: build the run, save its resolved recipe, loop, checkpoint."""
    help_request = _help_request(argv)
    if help_request is not None:
        fit_help(help_request)
    import yaml

    from qdil.config import finished
    from qdil.executors.base import ExecutorError
    from qdil.files import atomic_write, remove_stale_temporaries
    from qdil.provenance import record_start
    from qdil.qd.checkpoint import (
        CHECKPOINT,
        config_differences,
        load_checkpoint,
        read_checkpoint,
    )
    from qdil.qd.loop import run_qd
    from qdil.rewards.base import NonFiniteRewardError
    from qdil.tracking import check_wandb_login

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
    state = None
    if resume_dir is not None and (run_dir / CHECKPOINT).exists():
        state = read_checkpoint(run_dir / CHECKPOINT)
        _check_unchanged(state, yaml.safe_load(resolved), run_dir, config_differences)
        if finished(config.qd, state["iteration"], state["env_steps"]):  # nothing to run or write
            how = "--qd.iterations N continues it to N"
            spent = ""
            if config.qd.env_steps is not None:
                how = "--qd.iterations N and --qd.env_steps N continue it"
                spent = f", {state['env_steps']:,} env steps of a budget of {config.qd.env_steps:,}"
            print(
                f"{run_dir} is finished: iteration {state['iteration']} of "
                f"{config.qd.iterations}{spent}; nothing to do ({how})",
                file=sys.stderr,
            )
            return
    problem = check_wandb_login(config.logging.wandb)  # before the run writes anything
    if problem is not None:
        raise SystemExit(f"qdil fit: error: {problem}")
    for path in remove_stale_temporaries(run_dir, run_dir / CHECKPOINT.parent):
        print(f"removed {path}, left by a killed write", file=sys.stderr)
    if resume_dir is not None and state is None:
        print(
            f"{run_dir} has no checkpoint (the run stopped before its first one); "
            f"starting it over from its {CONFIG_NAME}",
            file=sys.stderr,
        )
    fresh = not run_dir.exists()
    made = [folder for folder in run_dir.absolute().parents if not folder.exists()]
    run_dir.mkdir(parents=True, exist_ok=True)
    try:
        atomic_write(run_dir / CONFIG_NAME, lambda file: file.write(resolved.encode()))
        init = parser.instantiate(config)
        run = build(init, name, run_dir, resolved, resume=state is not None)
    except BaseException:
        if fresh:  # a run that never started leaves no directory behind, nor its root
            shutil.rmtree(run_dir, ignore_errors=True)
            for folder in made:  # innermost first; one another process wrote into stays
                with contextlib.suppress(OSError):
                    folder.rmdir()
        raise
    if state is not None:
        load_checkpoint(run, state)
        del state  # the checkpoint's bytes are restored into the run; free them
        print(f"resuming {run_dir} at iteration {run.state.iteration}", file=sys.stderr)
    tracker = cast("Tracker", run.tracker)  # build_run's; the loop sees only its RunTracker face
    if tracker.csv.path.exists():  # rows logged after the checkpoint (all, if none)
        tracker.csv.truncate(run.state.iteration)
    note = record_start(run_dir, run.state.iteration)
    if note is not None:
        print(f"qdil fit: warning: {run_dir} is {note}", file=sys.stderr)
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
        run.executor.close()
    if tracker.wants_videos:
        tracker.log_videos(_render_for_wandb(run_dir, tracker.logging.videos), run.state.iteration)
    tracker.finish(run)
    print(f"run directory: {run_dir}", file=sys.stderr)


def _check_unchanged(
    state: dict[str, Any], resolved: dict[str, Any], run_dir: Path, differences: Any
) -> None:
    """Refuse a resume whose recipe differs from the one stored with its checkpoint.

    Raises:
        SystemExit: naming the keys that differ and what to do.
    """
    from qdil.upgrades import upgraded

    stored = state.get("config")
    if stored is None:  # written before checkpoints stored their recipe
        return
    changed = differences(upgraded(stored), resolved)
    if changed:
        lines = "\n".join(f"  {line}" for line in changed)
        raise SystemExit(
            f"qdil fit: error: {run_dir / CONFIG_NAME} no longer matches the recipe its "
            f"checkpoint was made with (checkpoint -> now):\n{lines}\n"
            "Restore these keys to resume, or start a new run from the edited file with "
            f"`qdil fit {run_dir / CONFIG_NAME} --name NEW_NAME`. Only qd.iterations, "
            "qd.env_steps, env.num_threads, executor.* and logging.* may change on resume."
        )


def build(init: Namespace, name: str, run_dir: Path, resolved: str, *, resume: bool) -> Run:
    """The run of an instantiated recipe (envs, reward model, scheduler, trackers)."""
    import yaml

    from qdil.run import build_run

    return build_run(
        name=name,
        run_dir=run_dir,
        seed=init.seed,
        env=init.env,
        policy=init.policy,
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


def _render_for_wandb(run_dir: Path, count: int) -> list:
    """``count`` elites of the deployable archive, spread over the measures, as videos.

    They stay in ``RUN_DIR/videos/wandb``; without GL (or elites) one line says why, and none.
    """
    from qdil.envs.gl import GLUnavailableError
    from qdil.evaluation.video import render_elites

    try:
        return render_elites(run_dir, run_dir / "videos" / "wandb", which="deployable", top=count)
    except (GLUnavailableError, ValueError) as error:  # no GL here, or no elite yet
        first = str(error).splitlines()[0]
        print(f"W&B videos skipped (logging.videos=0 turns them off): {first}", file=sys.stderr)
        return []
