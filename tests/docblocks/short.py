"""The docs test's one switch: ``QDIL_DOCS_SHORT=1`` shortens every ``qdil fit`` to seconds.

The docs' commands train for minutes to days. Under the switch (the docs test sets it unless
it is given as 0), the test's shell runs ``qdil`` through this file, which appends :data:`TINY`
to every new run, and to every trial of a ``qdil sweep`` (of a search: two trials; of a
table: its first seed; of a spec: each stage's first seed and grid point): one QD
iteration of a handful of simulations on 50-step episodes, the sizes of ``recipes/smoke/``.
Overrides given later win in the recipe parser, so whatever iterations or sizes a command
sets, the run stays tiny; everything else of the command (the recipe, the reward model and
its options, the name, the seed) runs as written, except that a model's offline pretraining
(:data:`PRETRAINING`) is cut to one pass. A resumed run goes one iteration further.
Commands that train nothing (``--help``, ``--print_config``, ``--reward.help``) and the
other commands (eval, report, demos, render, rewards) are unchanged: their cost follows the
tiny run they read.

Run as ``python short.py ARGS...`` it is the ``qdil`` command with that rewriting.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import yaml

from qdil.sweeps.spec import is_spec

# recipes/smoke/walker_true.yaml's sizes (num_envs divisible by k + 1 for k = 1 and 2 feet),
# ten cells per measure, one demonstration episode for the reward model's update, and no
# W&B videos at the end (tests/tracking/test_wandb.py covers them)
TINY = [
    "--qd.iterations", "1",
    "--env.num_envs", "6",
    "--env.max_episode_steps", "50",
    "--rl.init_args.rollout_length", "16",
    "--rl.init_args.jacobian_iterations", "2",
    "--rl.init_args.walk_iterations", "2",
    "--rl.init_args.num_minibatches", "2",
    "--rl.init_args.update_epochs", "2",
    "--qd.cells", "10",
    "--qd.branch_episodes", "1",
    "--qd.mean_episodes", "2",
    "--qd.emitter.init_args.batch_size", "4",
    "--demos.num_episodes", "1",
    "--logging.progress", "false",
    "--logging.videos", "0",
]  # fmt: skip
ES_PAIRS = ["--rl.init_args.pairs", "2"]  # ES gradients: four perturbed policies
ONE_MORE = ["--qd.iterations", "2"]  # a resumed tiny run: one iteration past its first
NOTHING_RUNS = {"-h", "--help", "--print_config", "--reward.help"}
# reward options that train offline before the first iteration (GIRIL's VAE: 10,000 passes
# over the demonstrations in the paper's recipes), shortened where the model has them
PRETRAINING = {"pretrain_epochs": "1"}


def enabled() -> bool:
    """Whether the switch is on: ``QDIL_DOCS_SHORT`` set to anything but empty or 0."""
    return os.environ.get("QDIL_DOCS_SHORT", "") not in ("", "0")


def pretraining(fit_argv: list[str]) -> list[str]:
    """Overrides of :data:`PRETRAINING` for the options the fit's reward model has."""
    from qdil.cli import parse_fit

    try:
        config, _, _ = parse_fit(fit_argv)
    except (SystemExit, Exception):  # a bad command: qdil itself says what is wrong
        return []
    options = getattr(config.reward, "init_args", None) or {}  # true_reward has none
    return [
        arg
        for key, value in PRETRAINING.items()
        if key in options
        for arg in (f"--reward.{key}", value)
    ]


def fitted(argv: list[str]) -> list[str]:
    """:data:`TINY` for the fit ``argv``: the estimator's options it has, or none (``rl: null``).

    VPPO's options shorten VPPO; ES gradients play :data:`ES_PAIRS` pairs; gradient-free
    emitters take no ``rl`` option.
    """
    from qdil.cli import parse_fit

    try:
        config, _, _ = parse_fit(argv)
        init_args = getattr(config.rl, "init_args", None) if config.rl else None
        options = set(init_args.as_dict()) if init_args else set()
    except (SystemExit, Exception):  # a bad command: qdil itself says what is wrong
        return TINY
    tiny = []
    for flag, value in zip(TINY[::2], TINY[1::2], strict=True):
        if not flag.startswith("--rl.init_args.") or flag.rpartition(".")[2] in options:
            tiny += [flag, value]
    return [*tiny, *(ES_PAIRS if "pairs" in options else [])]


def first_seed(argv: list[str]) -> list[str]:
    """``argv`` with only the first seed after ``--seeds`` (a sweep's table, one row)."""
    if "--seeds" not in argv:
        return argv
    at = argv.index("--seeds") + 1
    end = at
    while end < len(argv) and not argv[end].startswith("-"):
        end += 1
    return [*argv[:at], *argv[at : at + 1], *argv[end:]]


def one_point(spec: Path) -> Path:
    """A copy of the sweep spec ``spec`` beside it with each stage's first seed and grid point.

    The stages, recipes, overrides, demonstrations and reports run as written; a table of
    seeds × grid points becomes one trial per recipe and stage.
    """
    content = yaml.safe_load(spec.read_text())
    for stage in content.get("stages") or []:
        if isinstance(stage, dict) and stage.get("seeds"):
            stage["seeds"] = stage["seeds"][:1]
        if isinstance(stage, dict) and isinstance(stage.get("grid"), dict):
            stage["grid"] = {key: values[:1] for key, values in stage["grid"].items()}
    short = spec.with_name(f".{spec.stem}.short.yaml")
    short.write_text(yaml.safe_dump(content, sort_keys=False))
    return short


def shortened(argv: list[str]) -> list[str]:
    """The ``qdil`` arguments ``argv`` with a tiny run's overrides appended to a fit or sweep.

    A sweep runs one seed of its ``--seeds`` (a spec: each stage's first seed and grid
    point), each trial a tiny run.
    """
    if argv and argv[0] == "sweep" and not NOTHING_RUNS.intersection(argv):
        searched = ["--samples", "2"] if "--search" in argv else []  # two tiny trials
        argv = first_seed(argv)
        if len(argv) > 1 and not argv[1].startswith("-") and is_spec(Path(argv[1])):
            argv = [argv[0], str(one_point(Path(argv[1]))), *argv[2:]]
        return [*argv, *TINY, *searched]  # every trial a tiny run (overrides reach each)
    if not argv or argv[0] != "fit" or NOTHING_RUNS.intersection(argv):
        return argv
    if "--resume" in argv:  # a resumed run does not pretrain again
        return [*argv, *ONE_MORE]
    tiny = [*argv, *fitted(argv[1:])]
    return [*tiny, *pretraining(tiny[1:])]


if __name__ == "__main__":
    from qdil.cli import main

    main(shortened(sys.argv[1:]) if enabled() else sys.argv[1:])
