"""Where the time of a QD iteration goes, and its env-steps/s against bare stepping.

Compiles the physics kernels, runs a few iterations of a recipe (default: the laptop
Walker2d PPGA recipe) with timers wrapped around the components, then steps the same task
with random actions to measure the bare stepping rate of the environment, in the same
process:

- physics: ``MujocoBatch.step`` and ``reset`` (the numba kernels);
- policy inference: sampling actions during rollouts and evaluations;
- PPO updates: GAE and the minibatch epochs;
- reward model: ``predict_reward`` and ``update``;
- archive work: the pyribs scheduler's ask/tell and the passive archives' inserts;
- other: Python around them (rollout bookkeeping, env step bookkeeping, metrics).

Usage::

    python benchmarks/bench_iteration.py [RECIPE] [--iterations 3] [--clock wall|cpu] \
        [--KEY VALUE ...]

``--clock cpu`` times with this process's CPU time (for a machine other processes load);
further ``--KEY VALUE`` pairs override the recipe, e.g. ``--env.num_envs 1026``.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TIMES: dict[str, float] = defaultdict(float)
# wall time by default; ``--clock cpu`` switches every timer to this process's CPU time
CLOCK = time.perf_counter
# components count only inside QD iterations: not the run's setup, not the bare stepping
INSIDE = [False]


def timed(owner: object, name: str, label: str) -> None:
    """Wrap ``owner.name`` so that its time (:data:`CLOCK`) accumulates under ``label``."""
    original = getattr(owner, name)
    outermost = label == "iteration"

    def wrapper(*args, **kwargs):
        if not (INSIDE[0] or outermost):
            return original(*args, **kwargs)
        INSIDE[0] = True
        start = CLOCK()
        try:
            return original(*args, **kwargs)
        finally:
            TIMES[label] += CLOCK() - start
            INSIDE[0] = not outermost

    setattr(owner, name, wrapper)


def instrument() -> None:
    from ribs.schedulers import Scheduler

    from qdil.envs import physics
    from qdil.qd import archives, loop, vppo
    from qdil.rl import collect

    timed(physics.MujocoBatch, "step", "physics")
    timed(physics.MujocoBatch, "reset", "physics")
    # the per-step sampler (older code: the ``act`` function, for before/after comparisons)
    if hasattr(collect, "PolicySampler"):
        timed(collect.PolicySampler, "sample", "policy inference")
    else:
        timed(collect, "act", "policy inference")
    timed(vppo, "ppo_update", "PPO updates")  # the name VPPO's phases call
    for name in ("ask_dqd", "tell_dqd", "ask", "tell"):
        timed(Scheduler, name, "archive work")
    timed(archives.RunArchives, "add", "archive work")
    timed(loop, "qd_iteration", "iteration")
    original = loop.reward_functions

    def reward_functions(run):
        train, evaluate = original(run)
        model = run.reward
        if not getattr(model, "_timed", False):
            timed(model, "predict_reward", "reward model")
            timed(model, "update", "reward model")
            model._timed = True
        return train, evaluate

    loop.reward_functions = reward_functions


def warm_up() -> None:
    """Compile the physics kernels before anything is timed.

    numba compiles the step and reset kernels at their first call, in this process once
    (they call MuJoCo through pointers, so they cannot be cached on disk). Left in, that
    one-time cost would land in the first iteration's physics and lower a few-iteration
    ratio that a 120-iteration run never sees. Every task shares the kernels' signature.
    """
    from qdil.envs.vector import LocomotionVectorEnv

    env = LocomotionVectorEnv("Hopper-v5", 2, autoreset_mode="Disabled")
    env.reset(seed=0)
    env.step(np.zeros((2, 3)), mask=np.array([True, False]))


def bare_rate(task: str, num_envs: int, steps: int, repeats: int = 3) -> float:
    """Env-steps/s of random actions on the task's batched env (median of ``repeats``).

    A median of several passes, because one pass of a few hundred steps moved by about
    10 % between runs on a loaded machine, as much as the changes it is compared with.
    """
    import gymnasium as gym

    env = gym.make_vec(f"qdil/{task}", num_envs=num_envs, autoreset_mode="SameStep")
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    low, high = env.single_action_space.low, env.single_action_space.high
    actions = rng.uniform(low, high, size=(steps, num_envs, low.size))
    env.step(actions[0])
    rates = []
    for _ in range(repeats):
        start = CLOCK()
        for a in actions:
            env.step(a)
        rates.append(steps * num_envs / (CLOCK() - start))
    return float(np.median(rates))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("recipe", nargs="?", default=str(ROOT / "recipes" / "walker_ppga.yaml"))
    parser.add_argument("--iterations", type=int, default=3)
    parser.add_argument(
        "--clock",
        choices=("wall", "cpu"),
        default="wall",
        help="cpu: time with this process's CPU time (all its threads), for comparisons on a "
        "machine that other processes load; meaningful with one physics and torch thread",
    )
    # anything else goes to ``qdil fit`` as a recipe override, e.g. ``--env.num_envs 255``
    # for the scaling ratios (N must split among the k+1 VPPO copies: 3 on Walker2d)
    args, overrides = parser.parse_known_args()
    global CLOCK
    CLOCK = time.process_time if args.clock == "cpu" else time.perf_counter
    # the run happens in a temporary directory: resolve the recipe against the caller's
    # working directory first (a relative path used to fail with "recipe ... not found")
    args.recipe = str(Path(args.recipe).resolve())
    warm_up()
    instrument()
    import qdil
    from qdil.cli import main as qdil_main

    with tempfile.TemporaryDirectory() as tmp:
        os.chdir(tmp)
        start = time.perf_counter()
        qdil_main(
            [
                "fit",
                args.recipe,
                "--qd.iterations",
                str(args.iterations),
                "--name",
                "bench",
                "--logging.wandb",
                "disabled",
                "--logging.progress",
                "false",
                "--logging.checkpoint_every",
                str(10**6),
                *overrides,
            ]
        )
        import csv

        with open(Path(tmp) / "runs" / "bench" / "metrics.csv", newline="") as file:
            rows = list(csv.DictReader(file))
        import yaml

        config = yaml.safe_load((Path(tmp) / "runs" / "bench" / "config.yaml").read_text())
    total = TIMES["iteration"]  # the loop's own iterations, timed like the components
    steps = float(rows[-1]["perf/env_steps"])
    task, num_envs = config["env"]["task"], config["env"]["num_envs"]
    bare = bare_rate(task, num_envs, steps=300)
    wall = time.perf_counter() - start
    print(
        f"# {Path(args.recipe).name}: {args.iterations} iterations of {task}, "
        f"qdil {qdil.__version__}, {os.cpu_count()} CPUs, wall {wall:.0f} s, "
        f"{args.clock} clock"
    )
    print("| component | seconds per iteration | share |\n|---|---|---|")
    accounted = 0.0
    for label in ("physics", "policy inference", "PPO updates", "reward model", "archive work"):
        seconds = TIMES.get(label, 0.0)
        accounted += seconds
        print(f"| {label} | {seconds / args.iterations:.2f} | {100 * seconds / total:.1f} % |")
    other = total - accounted
    print(f"| other | {other / args.iterations:.2f} | {100 * other / total:.1f} % |")
    print(f"| **iteration** | **{total / args.iterations:.2f}** | 100 % |")
    rate = steps / total
    print(
        f"\nenv-steps/s over whole iterations: {rate:,.0f}; bare stepping of {task} with "
        f"{num_envs} envs (random actions): {bare:,.0f}; ratio {rate / bare:.2f}"
    )
    sys.stdout.flush()


if __name__ == "__main__":
    main()
