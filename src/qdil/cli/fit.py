"""``qdil fit``: parse a recipe (or a run to resume), build the run, loop, checkpoint."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from qdil.cli.args import plain_text
from qdil.rewards.names import rewrite_reward_flag

# Only the standard library at import time (see qdil.cli): torch, Lightning and pyribs load
# inside the functions that use them.
if TYPE_CHECKING:
    from jsonargparse import ArgumentParser, Namespace

    from qdil.recipe_load import LoadedRecipe
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


def _load(argv: list[str]) -> LoadedRecipe:
    """The checked recipe of ``qdil fit``'s arguments.

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
        return load_recipe(source, overrides, resume=resume)
    except RecipeError as error:
        raise SystemExit(str(error)) from None


def parse_fit(argv: list[str]) -> tuple[Namespace, Path | None, str]:
    """Parse ``qdil fit`` arguments; returns (config, run dir to resume or None, name stem).

    Raises:
        SystemExit: with a message naming the recipe key on a bad recipe.
    """
    loaded = _load(argv)
    return loaded.config, loaded.resume_dir, loaded.stem


def fit(argv: list[str]) -> None:
    """``qdil fit``: parse, open the run folder, loop to the end (:class:`qdil.experiment`)."""
    help_request = _help_request(argv)
    if help_request is not None:
        fit_help(help_request)
    loaded = _load(argv)  # a misspelt key is refused before the run's packages load
    from qdil.executors.base import ExecutorError
    from qdil.experiment import Experiment, RunFolder
    from qdil.rewards.base import NonFiniteRewardError
    from qdil.tracking import check_wandb_login

    folder = RunFolder.of(loaded)
    run_dir, config = folder.run_dir, folder.loaded.config
    if folder.finished:  # nothing to run or write
        state = folder.state or {}
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
    experiment = Experiment.open(folder)
    for note in experiment.notes:
        print(note if not note.startswith("warning") else f"qdil fit: {note}", file=sys.stderr)
    run = experiment.run
    try:
        experiment.fit()
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
    tracker = cast("Tracker", run.tracker)
    if tracker.wants_videos:
        tracker.log_videos(_render_for_wandb(run_dir, tracker.logging.videos), run.state.iteration)
    tracker.finish(run)
    print(f"run directory: {run_dir}", file=sys.stderr)


def build(init: Namespace, name: str, run_dir: Path, resolved: str, *, resume: bool) -> Run:
    """The run of an instantiated recipe (:func:`qdil.experiment.build_recipe`).

    ``resume``: a checkpoint will be restored into it (its reward pretraining is skipped).
    """
    from qdil.experiment import build_recipe

    return build_recipe(init, name, run_dir, resolved, resume=resume)


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
