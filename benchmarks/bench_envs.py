"""Env-steps per second of qdil's batched tasks against gymnasium and raw MuJoCo, in one run.

For each task, with random actions drawn up front:

- ``qdil``: ``gymnasium.make_vec("qdil/<Task>-v5", num_envs=N)`` (foot-contact measures on,
  autoreset on), physics on every core, and with one physics thread;
- ``gym sync``: ``gymnasium.make_vec("<Task>-v5", num_envs=N, vectorization_mode="sync")``;
- ``raw mj_step``: one ``MjData`` stepped by ``mujoco.mj_step(m, d, frame_skip)`` in a Python
  loop on one core, reset when unhealthy: the bare cost of the physics.

Each number is the median of ``--reps`` timed repetitions after one warm-up. Ratios are
against gymnasium's sync vector env measured in the same run.

Usage::

    python benchmarks/bench_envs.py [--tasks Walker2d-v5 ...] [--num-envs 64] [--steps 200]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time

import gymnasium as gym
import mujoco
import numpy as np

import qdil  # noqa: F401  (registers qdil/ tasks)
from qdil.envs.tasks import make_task


def _median_rate(run, steps: int, reps: int) -> float:
    run()  # warm-up: JIT compilation, caches
    rates = []
    for _ in range(reps):
        start = time.perf_counter()
        run()
        rates.append(steps / (time.perf_counter() - start))
    return statistics.median(rates)


def bench_vector(env: gym.vector.VectorEnv, actions: np.ndarray) -> tuple:
    env.reset(seed=0)

    def run() -> None:
        for a in actions:
            env.step(a)

    return run, actions.shape[0] * actions.shape[1]


def bench_raw(task_id: str, actions: np.ndarray) -> tuple:
    task = make_task(task_id)
    model = mujoco.MjModel.from_xml_path(str(task.xml_path))
    data = mujoco.MjData(model)
    flat = actions.reshape(-1, actions.shape[-1]).astype(np.float64)
    qpos0 = data.qpos.copy()
    healthy_z = getattr(task, "healthy_z_range", None)
    z_index = 2 if task_id in ("Humanoid-v5", "Ant-v5") else 1

    def run() -> None:
        for a in flat:
            data.ctrl[:] = a
            mujoco.mj_step(model, data, task.frame_skip)
            if healthy_z is not None and not healthy_z[0] < data.qpos[z_index] < healthy_z[1]:
                mujoco.mj_resetData(model, data)
                data.qpos[:] = qpos0

    return run, flat.shape[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--tasks", nargs="+", default=["Walker2d-v5", "HalfCheetah-v5", "Humanoid-v5"]
    )
    parser.add_argument("--num-envs", type=int, default=64)
    parser.add_argument("--steps", type=int, default=200, help="vector steps per repetition")
    parser.add_argument("--reps", type=int, default=5)
    args = parser.parse_args()

    print(
        f"# {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"mujoco {mujoco.__version__}, gymnasium {gym.__version__}, N={args.num_envs}"
    )
    header = ("task", "qdil", "qdil 1 thread", "gym sync", "raw mj_step", "qdil/gym", "qdil/raw")
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    rng = np.random.default_rng(0)
    for task_id in args.tasks:
        probe = gym.make_vec(task_id, num_envs=1, vectorization_mode="sync")
        low, high = probe.single_action_space.low, probe.single_action_space.high
        shape = (args.steps, args.num_envs, low.size)
        actions = rng.uniform(low, high, size=shape).astype(np.float32)
        rates = {}
        n = args.num_envs
        vector_envs = {
            "qdil": gym.make_vec(f"qdil/{task_id}", num_envs=n),
            "qdil1": gym.make_vec(f"qdil/{task_id}", num_envs=n, num_threads=1),
            "gym": gym.make_vec(task_id, num_envs=n, vectorization_mode="sync"),
        }
        for name, env in vector_envs.items():
            rates[name] = _median_rate(*bench_vector(env, actions), args.reps)
        rates["raw"] = _median_rate(
            *bench_raw(task_id, actions[: max(1, args.steps // 8)]), args.reps
        )
        row = (
            task_id,
            f"{rates['qdil']:,.0f}",
            f"{rates['qdil1']:,.0f}",
            f"{rates['gym']:,.0f}",
            f"{rates['raw']:,.0f}",
            f"{rates['qdil'] / rates['gym']:.2f}x",
            f"{rates['qdil'] / rates['raw']:.2f}x",
        )
        print("| " + " | ".join(row) + " |", flush=True)


if __name__ == "__main__":
    main()
