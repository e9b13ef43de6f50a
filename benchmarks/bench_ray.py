"""One QD iteration's simulation work, locally and on 1 and 2 Ray workers, on this machine.

Runs what a QD iteration asks of the executor for a mid-size setting (default: Walker2d,
510 training simulations, a multiple of k + 1 = 3 as VPPO needs, 64 branches ×
``--episodes`` episodes): the Jacobian phase (``--jacobian`` rollouts of 3 policies), the
branch and mean evaluations, and the walk (``--walk`` rollouts of 1 policy), with the PPO
updates left out so that the numbers compare the executors, not the head. Prints
env-steps/s for each executor, the ratio to local, and the bytes each iteration sends and
receives. The results are bit-identical across executors (``tests/executors``); this
measures only speed.

Usage::

    python benchmarks/bench_ray.py [--num-envs 510] [--branches 64] [--episodes 2]
        [--rollout 64] [--jacobian 2] [--walk 2] [--workers 1 2] [--repeats 2]
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
import torch

from qdil.envs.vector import LocomotionVectorEnv
from qdil.executors import LocalExecutor, RayExecutor
from qdil.qd.scoring import Scorer
from qdil.qd.vppo import VPPO
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from qdil.run import set_up_policies


def iteration(algo: VPPO, scorer: Scorer, args: argparse.Namespace, seed: int) -> int:
    """The executor's share of one QD iteration; returns the env steps it simulated."""
    theta = VectorizedActor.initial_solution(algo.obs_dim, algo.action_dim, algo.actor_hidden, 0)
    stats = RunningMeanStd(1, (algo.obs_dim,))
    copies = algo._actor(np.repeat(theta[None], 3, axis=0))
    steps = 0
    algo.executor.start(seed)
    for _ in range(args.jacobian):
        algo.executor.collect(
            copies, RunningMeanStd.stack([stats] * 3), args.rollout, algo.generator, False
        )
        steps += args.rollout * args.num_envs
    branches = np.repeat(theta[None], args.branches, axis=0)
    branches += 0.01 * np.random.default_rng(seed).standard_normal(branches.shape)
    many = RunningMeanStd.stack([stats] * args.branches)
    steps += scorer.evaluate(branches.astype(np.float32), many, args.episodes, seed).env_steps
    steps += scorer.evaluate(theta[None], stats, args.branches * args.episodes, seed).env_steps
    walker = algo._actor(theta[None])
    algo.executor.start(seed + 1)
    for _ in range(args.walk):
        algo.executor.collect(walker, stats, args.rollout, algo.generator, True)
        steps += args.rollout * args.num_envs
    return steps


def measure(executor, args: argparse.Namespace) -> tuple[float, int, int]:
    algo = VPPO(rollout_length=args.rollout)
    kwargs = {"max_episode_steps": args.horizon, "num_threads": args.threads}
    train = LocomotionVectorEnv(args.task, args.num_envs, autoreset_mode="SameStep", **kwargs)
    size = args.branches * args.episodes
    evaluation = LocomotionVectorEnv(args.task, size, autoreset_mode="Disabled", **kwargs)
    _, scorer, _ = set_up_policies(train, evaluation, algo, executor=executor)
    iteration(algo, scorer, args, 100)  # warm-up: numba kernels, worker start-up
    sent0 = getattr(executor, "bytes_sent", 0)
    received0 = getattr(executor, "bytes_received", 0)
    best = 0.0
    for r in range(args.repeats):
        tic = time.perf_counter()
        steps = iteration(algo, scorer, args, r)
        best = max(best, steps / (time.perf_counter() - tic))
    sent = (getattr(executor, "bytes_sent", 0) - sent0) // args.repeats
    received = (getattr(executor, "bytes_received", 0) - received0) // args.repeats
    executor.close()
    return best, sent, received


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--task", default="Walker2d-v5")
    parser.add_argument(
        "--num-envs", type=int, default=510, help="training simulations, a multiple of k + 1"
    )
    parser.add_argument("--branches", type=int, default=64)
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--horizon", type=int, default=200)
    parser.add_argument("--rollout", type=int, default=64)
    parser.add_argument("--jacobian", type=int, default=2)
    parser.add_argument("--walk", type=int, default=2)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--threads", type=int, default=None, help="local physics threads")
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    cores = os.cpu_count() or 1
    args.threads = args.threads or min(cores, max(args.workers))
    torch.set_num_threads(args.threads)
    import ray

    ray.init(num_cpus=max(args.workers), include_dashboard=False, log_to_driver=False)
    print(
        f"{args.task}: {args.num_envs} sims × {args.rollout} steps × {args.jacobian}+"
        f"{args.walk} rollouts, {args.branches} branches × {args.episodes} episodes "
        f"(horizon {args.horizon}); {cores} cores"
    )
    local, _, _ = measure(LocalExecutor(), args)
    print(f"local ({args.threads} physics threads): {local:,.0f} env-steps/s")
    for workers in args.workers:
        sps, sent, received = measure(RayExecutor(num_workers=workers), args)
        print(
            f"ray, {workers} worker(s) × 1 thread: {sps:,.0f} env-steps/s, "
            f"ratio to local {sps / local:.2f}; per iteration sent {sent / 1e6:.1f} MB, "
            f"received {received / 1e6:.1f} MB"
        )
    ray.shutdown()


if __name__ == "__main__":
    main()
