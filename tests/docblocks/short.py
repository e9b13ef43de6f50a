"""The docs test's one switch: ``QDIL_DOCS_SHORT=1`` shortens every ``qdil fit`` to seconds.

The docs' commands train for minutes to days. Under the switch (the docs test sets it unless
it is given as 0), the test's shell runs ``qdil`` through this file, which appends :data:`TINY`
to every new run: one QD iteration of a handful of simulations on 50-step episodes, the
sizes of ``recipes/smoke/``. Overrides given later win in the recipe parser, so whatever
iterations or sizes a command sets, the run stays tiny; everything else of the command (the
recipe, the reward model and its options, the name, the seed) runs as written. A resumed run
goes one iteration further. Commands that train nothing (``--help``, ``--print_config``,
``--reward.help``) and the other commands (eval, report, demos, render, rewards) are
unchanged: their cost follows the tiny run they read.

Run as ``python short.py ARGS...`` it is the ``qdil`` command with that rewriting.
"""

from __future__ import annotations

import os
import sys

# recipes/smoke/walker_true.yaml's sizes (num_envs divisible by k + 1 for k = 1 and 2 feet),
# ten cells per measure, and one demonstration episode for the reward model's update
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
]  # fmt: skip
ONE_MORE = ["--qd.iterations", "2"]  # a resumed tiny run: one iteration past its first
NOTHING_RUNS = {"-h", "--help", "--print_config", "--reward.help"}


def enabled() -> bool:
    """Whether the switch is on: ``QDIL_DOCS_SHORT`` set to anything but empty or 0."""
    return os.environ.get("QDIL_DOCS_SHORT", "") not in ("", "0")


def shortened(argv: list[str]) -> list[str]:
    """The ``qdil`` arguments ``argv`` with a tiny run's overrides appended to a fit."""
    if not argv or argv[0] != "fit" or NOTHING_RUNS.intersection(argv):
        return argv
    if "--resume" in argv:
        return [*argv, *ONE_MORE]
    return [*argv, *TINY]


if __name__ == "__main__":
    from qdil.cli import main

    main(shortened(sys.argv[1:]) if enabled() else sys.argv[1:])
