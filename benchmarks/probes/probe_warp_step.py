"""Where one env step of the Warp backend spends its time, and what CUDA graphs would save.

For Walker2d-v5 with N simulations on a CUDA device, milliseconds per call (device
synchronised before and after each timed block, mean over ``--reps`` calls):

- ``env.step`` through gymnasium's numpy face (host copies included), with the backend's
  graphs (the default) and with every kernel launched from Python (``graphs`` off), and one
  step of the torch face (:class:`qdil.envs.torch_vector.TorchVectorEnv`, no host copy),
  autoreset on;
- one ``mjw.step`` substep, the frame skip's ``mjw.step`` calls, the sensor pass
  (``kinematics``, ``collision``, ``sensor_pos``) and ``mjw.forward``, as the backend launches
  them from Python;
- the same frame skip of ``mjw.step`` captured once in a CUDA graph (``wp.ScopedCapture``) and
  replayed with ``wp.capture_launch``: the cost without Python's kernel launches.

Then a ``cProfile`` of the numpy-face steps, top functions by own time. One command on a
CUDA machine with the warp extra::

    python benchmarks/probes/probe_warp_step.py --num-envs 4096
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time
from collections.abc import Callable

import numpy as np
import torch


def timed(fn: Callable[[], object], reps: int, sync: Callable[[], None]) -> float:
    """Milliseconds per call of ``fn`` after one untimed call (compiles on first use)."""
    fn()
    sync()
    start = time.perf_counter()
    for _ in range(reps):
        fn()
    sync()
    return 1e3 * (time.perf_counter() - start) / reps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--num-envs", type=int, default=4096)
    parser.add_argument("--reps", type=int, default=20)
    parser.add_argument("--device", default="cuda")
    args = parser.parse_args()

    from qdil.envs.torch_vector import TorchVectorEnv
    from qdil.envs.vector import LocomotionVectorEnv

    n, reps = args.num_envs, args.reps
    env = LocomotionVectorEnv("Walker2d-v5", n, backend="warp", device=args.device)
    physics = env.physics
    wp, mjw, model, data = physics.warp, physics.mjw, physics.wmodel, physics.wdata
    frame_skip = env.task.frame_skip

    def sync() -> None:
        wp.synchronize_device(physics.warp_device)

    env.reset(seed=0)
    rng = np.random.default_rng(0)
    low, high = env.single_action_space.low, env.single_action_space.high
    actions = rng.uniform(low, high, (n, low.size))
    rows = [("env.step, numpy face", timed(lambda: env.step(actions), reps, sync))]
    graphs = physics.graphs
    graphs.enabled, saved, graphs.recorded = False, graphs.recorded, {}
    rows.append(("env.step, numpy face, graphs off", timed(lambda: env.step(actions), reps, sync)))
    graphs.enabled, graphs.recorded = True, saved

    face_env = LocomotionVectorEnv(
        "Walker2d-v5", n, autoreset_mode="SameStep", backend="warp", device=args.device
    )
    face = TorchVectorEnv(face_env)
    face.reset(seed=0)
    device_actions = torch.as_tensor(actions, dtype=torch.float32, device=physics.torch_device)
    rows.append(("TorchVectorEnv.step", timed(lambda: face.step(device_actions), reps, sync)))

    with wp.ScopedDevice(physics.device):
        rows.append(("mjw.step (one substep)", timed(lambda: mjw.step(model, data), reps, sync)))

        def substeps() -> None:
            for _ in range(frame_skip):
                mjw.step(model, data)

        rows.append((f"mjw.step x {frame_skip} (frame skip)", timed(substeps, reps, sync)))

        def sensors() -> None:
            mjw.kinematics(model, data)
            mjw.collision(model, data)
            mjw.sensor_pos(model, data)

        rows.append(("kinematics + collision + sensor_pos", timed(sensors, reps, sync)))
        rows.append(("mjw.forward", timed(lambda: mjw.forward(model, data), reps, sync)))
        if physics.torch_device.type == "cuda":
            with wp.ScopedCapture() as capture:
                substeps()
            graph = capture.graph
            rows.append(
                (
                    f"mjw.step x {frame_skip}, one CUDA graph replay",
                    timed(lambda: wp.capture_launch(graph), reps, sync),
                )
            )

    print(f"Walker2d-v5, N = {n:,}, device {physics.device}, {reps} calls each\n")
    print("| call | ms per call | env-steps/s at this cost |")
    print("|---|---|---|")
    for name, ms in rows:
        print(f"| {name} | {ms:.2f} | {n / (ms / 1e3):,.0f} |")

    profile = cProfile.Profile()
    profile.enable()
    for _ in range(reps):
        env.step(actions)
    sync()
    profile.disable()
    print(f"\ncProfile of {reps} numpy-face steps, top 15 by own time:")
    pstats.Stats(profile).sort_stats("tottime").print_stats(15)


if __name__ == "__main__":
    main()
