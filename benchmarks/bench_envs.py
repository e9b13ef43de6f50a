"""Env-steps per second of qdil's batched tasks against gymnasium and raw MuJoCo, in one run.

For each task, with random actions drawn up front:

- ``qdil``: ``gymnasium.make_vec("qdil/<Task>-v5", num_envs=N)`` (foot-contact measures on,
  autoreset on), physics on every core, and with one physics thread;
- ``gym sync``: ``gymnasium.make_vec("<Task>-v5", num_envs=N, vectorization_mode="sync")``;
- ``envpool``: ``envpool.make_gymnasium("<Task>-v4", num_envs=N, batch_size=N)`` (envpool
  1.2.5 has the v4 tasks, the same bodies as v5 but for v5's model fixes; it computes no foot
  contacts), on every core and on one thread, when envpool is installed
  (``pip install envpool==1.2.5``); the table says "not installed" otherwise;
- ``raw mj_step``: one ``MjData`` stepped by ``mujoco.mj_step(m, d, frame_skip)`` in a Python
  loop on one core, reset when unhealthy: the bare cost of the physics.

The contestants run in alternating rounds (one timed repetition of each per round, after one
warm-up each), so a machine whose load drifts slows them alike; each number is the median of
``--reps`` rounds. The all-core contestants (qdil, envpool, gymnasium) race first, then the
one-thread ones (qdil, envpool, the raw loop), each group built afresh so that no other
group's thread pool lives in the process meanwhile. Ratios compare numbers of the same run.

Usage::

    python benchmarks/bench_envs.py [--tasks Walker2d-v5 ...] [--num-envs 64 256] [--steps 200]
        [--reps 5] [--no-gym] [--all-cores-only]
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


def _median_rates(contestants: dict[str, tuple], reps: int) -> dict[str, float]:
    """Median env-steps/s of each ``(run, steps)`` contestant over alternating rounds."""
    for run, _ in contestants.values():
        run()  # warm-up: JIT compilation, caches
    rates: dict[str, list[float]] = {name: [] for name in contestants}
    for _ in range(reps):
        for name, (run, steps) in contestants.items():
            start = time.perf_counter()
            run()
            rates[name].append(steps / (time.perf_counter() - start))
    return {name: statistics.median(values) for name, values in rates.items()}


def make_envpool(task_id: str, num_envs: int, num_threads: int):
    """envpool's vector env of the task's v4 version, or ``None`` if envpool is missing."""
    try:
        import envpool
    except ImportError:
        return None
    env_id = task_id.replace("-v5", "-v4")
    return envpool.make_gymnasium(
        env_id, num_envs=num_envs, batch_size=num_envs, num_threads=num_threads, seed=0
    )


def bench_envpool(env, actions: np.ndarray) -> tuple:
    env.reset()
    actions = actions.astype(np.float64)

    def run() -> None:
        for a in actions:
            env.step(a)

    return run, actions.shape[0] * actions.shape[1]


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


def _contestants(
    task_id: str, n: int, actions: np.ndarray, cores: int, args, one_thread: bool
) -> dict[str, tuple]:
    """The contestants of one group: all cores (qdil, envpool, gymnasium) or one thread
    (qdil, envpool, the raw loop)."""
    threads = 1 if one_thread else cores
    suffix = "1" if one_thread else ""
    contestants = {
        f"qdil{suffix}": bench_vector(
            gym.make_vec(f"qdil/{task_id}", num_envs=n, num_threads=threads), actions
        )
    }
    pool = make_envpool(task_id, n, threads)
    if pool is not None:
        contestants[f"envpool{suffix}"] = bench_envpool(pool, actions)
    if one_thread:
        contestants["raw"] = bench_raw(task_id, actions[: max(1, args.steps // 8)])
    elif not args.no_gym:
        gym_env = gym.make_vec(task_id, num_envs=n, vectorization_mode="sync")
        contestants["gym"] = bench_vector(gym_env, actions)
    return contestants


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--tasks", nargs="+", default=["Walker2d-v5", "HalfCheetah-v5", "Humanoid-v5"]
    )
    parser.add_argument("--num-envs", type=int, nargs="+", default=[64])
    parser.add_argument("--steps", type=int, default=200, help="vector steps per repetition")
    parser.add_argument("--reps", type=int, default=5, help="alternating timed rounds")
    parser.add_argument("--no-gym", action="store_true", help="skip gymnasium's sync env")
    parser.add_argument(
        "--all-cores-only",
        action="store_true",
        help="skip the one-thread contestants and the raw loop (for large N)",
    )
    args = parser.parse_args()

    cores = os.cpu_count() or 1
    print(
        f"# {platform.processor() or platform.machine()}, {cores} CPUs, "
        f"mujoco {mujoco.__version__}, gymnasium {gym.__version__}"
    )
    header = ["task", "N", "qdil", "qdil 1 thread", "envpool", "envpool 1 thread"]
    header += ["gym sync", "raw mj_step", "qdil/envpool", "1 thread", "qdil/gym", "qdil/raw"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    rng = np.random.default_rng(0)
    for task_id in args.tasks:
        probe = gym.make_vec(task_id, num_envs=1, vectorization_mode="sync")
        low, high = probe.single_action_space.low, probe.single_action_space.high
        for n in args.num_envs:
            actions = rng.uniform(low, high, size=(args.steps, n, low.size)).astype(np.float32)
            # two groups, timed one after the other: every core, then one thread. Only one
            # group's environments exist at a time: with a second envpool pool alive in the
            # process, envpool's all-core rate swung from 13,000 to 20,900 env-steps/s
            # between runs (Walker2d, N = 64); alone it stays within a few percent
            rates = _median_rates(
                _contestants(task_id, n, actions, cores, args, one_thread=False), args.reps
            )
            if not args.all_cores_only:
                rates |= _median_rates(
                    _contestants(task_id, n, actions, cores, args, one_thread=True), args.reps
                )
            skipped = {"gym"} if args.no_gym else set()
            if args.all_cores_only:
                skipped |= {"qdil1", "envpool1", "raw"}
            print("| " + " | ".join(_row(task_id, n, rates, skipped)) + " |", flush=True)


def _row(task_id: str, n: int, rates: dict[str, float], skipped: set[str]) -> list[str]:
    def rate(name: str) -> str:
        if name in rates:
            return f"{rates[name]:,.0f}"
        return "skipped" if name in skipped else "not installed"

    def ratio(a: str, b: str) -> str:
        return f"{rates[a] / rates[b]:.2f}x" if a in rates and b in rates else "-"

    names = ("qdil", "qdil1", "envpool", "envpool1", "gym", "raw")
    cells = [task_id, str(n), *map(rate, names)]
    cells += [ratio("qdil", "envpool"), ratio("qdil1", "envpool1")]
    return [*cells, ratio("qdil", "gym"), ratio("qdil", "raw")]


if __name__ == "__main__":
    main()
