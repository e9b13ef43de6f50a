"""Throughput of the MuJoCo Warp backend, and one QD iteration on it.

Two measurements, printed as markdown tables:

1. env-steps/s of ``LocomotionVectorEnv(backend="warp")`` for several numbers of
   simulations N, random actions, autoreset on (host copies for gymnasium's API included),
   beside the C backend (``backend="mujoco"``, all cores) at the same N where that is quick;
2. one QD iteration of a recipe on the Warp backend (``qdil fit RECIPE --qd.iterations 1``,
   in a temporary directory): iteration seconds and the share spent in Warp physics.

On a CUDA machine (one command)::

    pip install -e ".[warp]" && python benchmarks/bench_warp.py

runs N = 1,024, 4,096 and 16,384 and the paper's WQDIL recipe
(``recipes/paper/walker_mcwae.yaml``, 3,000 simulations). Without CUDA the script runs on
Warp's CPU device, says so, and scales both down (N = 8 and 32, the smoke recipe): the CPU
device exists for tests, its figures are not the GPU's.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def steps_per_second(backend: str, device: str, task: str, num_envs: int, steps: int) -> float:
    """env-steps/s of ``steps`` vector steps after a warm-up (kernel compile excluded)."""
    from qdil.envs.vector import LocomotionVectorEnv

    env = LocomotionVectorEnv(task, num_envs, backend=backend, device=device)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    low, high = env.single_action_space.low, env.single_action_space.high
    actions = [rng.uniform(low, high, (num_envs, low.size)) for _ in range(8)]
    for i in range(3):  # warm-up: compiles Warp's kernels and numba's on first use
        env.step(actions[i % 8])
    start = time.perf_counter()
    for i in range(steps):
        env.step(actions[i % 8])
    return steps * num_envs / (time.perf_counter() - start)


def one_iteration(recipe: Path, device: str) -> tuple[float, float]:
    """(seconds, physics share) of one QD iteration of ``recipe`` on the Warp backend."""
    import torch

    from qdil.cli import main
    from qdil.envs import warp_physics

    spent = {"physics": 0.0}
    sync = torch.cuda.synchronize if device.startswith("cuda") else lambda: None
    # both faces end in these two (the numpy face's step and reset call them); on a GPU the
    # timer waits for the device around each call, so the share is the physics' own time
    for name in ("step_torch", "reset_where"):
        original = getattr(warp_physics.WarpBatch, name)

        def timed(*args, _original=original, **kwargs):
            sync()
            start = time.perf_counter()
            try:
                return _original(*args, **kwargs)
            finally:
                sync()
                spent["physics"] += time.perf_counter() - start

        setattr(warp_physics.WarpBatch, name, timed)
    with tempfile.TemporaryDirectory() as folder:
        os.chdir(folder)
        argv = ["fit", str(recipe), "--env.backend", "warp", "--env.device", device]
        argv += ["--qd.iterations", "1", "--name", "bench", "--logging.progress", "false"]
        argv += ["--logging.wandb", "disabled"]
        main(argv)
        with open(Path(folder) / "runs" / "bench" / "metrics.csv", newline="") as file:
            seconds = float(next(csv.DictReader(file))["perf/iter_seconds"])
        os.chdir(ROOT)
    # the loop's own clock; physics before the first iteration (none: setup only builds) aside
    return seconds, spent["physics"] / seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--device", default=None, help="cuda or cpu (default: cuda if present)")
    parser.add_argument("--sizes", default=None, help="comma-separated N (default by device)")
    parser.add_argument("--task", default="Walker2d-v5")
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--recipe", default=None, help="recipe of the QD iteration")
    parser.add_argument("--c-max", type=int, default=4096, help="largest N for the C backend")
    args = parser.parse_args()

    from qdil.envs.warp_startup import import_warp

    warp, _ = import_warp()
    cuda = warp.is_cuda_available()
    device = args.device or ("cuda" if cuda else "cpu")
    if device == "cpu":
        print(
            "No CUDA device: running on Warp's CPU device, scaled down (N = 8, 32; the smoke "
            "recipe). These figures are not a GPU's; run this on a CUDA machine for those.\n"
        )
    sizes = args.sizes or ("1024,4096,16384" if device != "cpu" else "8,32")
    recipe = Path(
        args.recipe
        or (
            "recipes/paper/walker_mcwae.yaml"
            if device != "cpu"
            else "recipes/smoke/walker_true.yaml"
        )
    )
    recipe = recipe if recipe.is_absolute() else ROOT / recipe
    if not recipe.exists():
        sys.exit(f"recipe {recipe} not found")

    print(f"| N | warp ({device}) env-steps/s | mujoco (C, all cores) env-steps/s | warp / C |")
    print("|---|---|---|---|")
    for num_envs in (int(n) for n in sizes.split(",")):
        fast = steps_per_second("warp", device, args.task, num_envs, args.steps)
        if num_envs <= args.c_max:
            c = steps_per_second("mujoco", "cpu", args.task, num_envs, args.steps)
            print(f"| {num_envs:,} | {fast:,.0f} | {c:,.0f} | {fast / c:.2f} |", flush=True)
        else:
            print(f"| {num_envs:,} | {fast:,.0f} | – | – |", flush=True)

    seconds, share = one_iteration(recipe, device)
    print("\n| recipe | device | iteration seconds | share in Warp physics |")
    print("|---|---|---|---|")
    print(f"| {recipe.relative_to(ROOT)} | {device} | {seconds:.1f} | {100 * share:.1f} % |")


if __name__ == "__main__":
    main()
