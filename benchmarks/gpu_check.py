"""The GPU check: tests, rollout throughput, host syncs and a paper-scale QD iteration.

One command on a machine with a CUDA GPU and the warp extra (at most about 8 minutes on one
H100 or H200)::

    python benchmarks/gpu_check.py --out gpu_check

measures, in steady state (kernels compiled and Warp graphs recorded before any clock runs):

0. where one training env step's time goes at the paper's N = 3,000: each recorded Warp
   sequence (substeps, sensor pass, reset, the reset's observed stages of ``forward``, and
   the whole ``forward`` for comparison), the torch face's step and a collector step, with
   the Warp launches and torch operators behind them and the solver's iterations; and one
   frame skip replayed at N = 1, 256, 3,000 and 16,384 (its latency floor);
1. rollout-face env-steps/s (:class:`qdil.envs.torch_vector.TorchVectorEnv`, no host copy,
   autoreset on) at N = 1,024, 4,096 and 16,384 simulations of Walker2d-v5;
2. host syncs per env step in a training rollout of the paper's size (the GPU recipe's
   3,000 simulations, 128 steps), counted by torch's sync debug mode;
3. two QD iterations of ``recipes/gpu/walker_mcwae.yaml`` through ``qdil fit``, with each
   phase's seconds from ``metrics.csv`` (the second iteration is the figure: the first
   records graphs and builds the reward model's optimiser state), then the same with θ_μ
   and its branches scored one after the other (``--env.eval_envs 3000``) as the baseline
   of scoring them side by side;
4. the GPU tests (``pytest -m gpu -n 0 tests/test_gpu.py tests/envs/test_warp_backend.py``).

It writes ``gpu_check.json`` (after every step, so a check cut short keeps what it
measured) and ``gpu_check.md``, the tables of docs/guides/gpu.md. ``--device cpu --quick``
runs the same code on Warp's CPU device, scaled down (the test suite runs it); its figures
are not a GPU's.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
import traceback
import warnings
import xml.etree.ElementTree as ElementTree
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RECIPE = ROOT / "recipes" / "gpu" / "walker_mcwae.yaml"
GPU_TESTS = ["tests/test_gpu.py", "tests/envs/test_warp_backend.py"]
PHASES = ("jacobian", "walk", "evaluate", "reward_update")
# the same recipe, scaled down for Warp's CPU device (--quick): every phase still runs
QUICK = [
    "--env.num_envs", "6", "--env.max_episode_steps", "40",
    "--rl.init_args.rollout_length", "8", "--rl.init_args.jacobian_iterations", "1",
    "--rl.init_args.walk_iterations", "1", "--rl.init_args.num_minibatches", "2",
    "--rl.init_args.update_epochs", "1", "--qd.emitter.init_args.batch_size", "3",
    "--qd.branch_episodes", "1", "--qd.mean_episodes", "3", "--reward.init_args.batch_size", "1000",
]  # fmt: skip


def _sync(device: str) -> Callable[[], None]:
    import torch

    return torch.cuda.synchronize if device.startswith("cuda") else lambda: None


def machine(device: str) -> dict[str, Any]:
    """The card, the host and the versions every figure depends on."""
    import mujoco
    import torch

    from qdil.envs.warp_physics import import_warp

    warp, mjw = import_warp()
    card = torch.cuda.get_device_name(device) if device.startswith("cuda") else "Warp CPU device"
    versions = {
        "torch": torch.__version__,
        "warp": warp.config.version,
        "mujoco": mujoco.__version__,
    }
    versions["mujoco_warp"] = getattr(mjw, "__version__", "unknown")
    return {
        "card": card,
        "cuda": torch.version.cuda,
        "cpu": platform.processor() or platform.machine(),
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "versions": versions,
    }


def rollout_throughput(device: str, sizes: list[int], steps: int) -> dict[str, float]:
    """env-steps/s of the rollouts' face, random actions, autoreset on, after a warm-up."""
    import torch

    from qdil.envs.torch_vector import TorchVectorEnv
    from qdil.envs.vector import LocomotionVectorEnv

    sync, result = _sync(device), {}
    for n in sizes:
        env = LocomotionVectorEnv(
            "Walker2d-v5", n, autoreset_mode="SameStep", backend="warp", device=device
        )
        face = TorchVectorEnv(env)
        face.reset(seed=0)
        generator = torch.Generator(device=face.device).manual_seed(0)
        dim = env.single_action_space.shape[0]
        actions = [
            torch.rand((n, dim), generator=generator, device=face.device) * 2 - 1 for _ in range(8)
        ]
        # warm-up past a reset-queue top-up: compiles kernels and records the Warp graphs
        for i in range(face.reset_depth + 2):
            face.step(actions[i % 8])
        sync()
        start = time.perf_counter()
        for i in range(steps):
            face.step(actions[i % 8])
        sync()
        result[str(n)] = steps * n / (time.perf_counter() - start)
        del face, env
    return result


class LaunchCount:
    """Counts Warp kernel launches (``warp.launch``/``launch_tiled``) made from Python."""

    def __enter__(self) -> LaunchCount:
        import warp

        self.count, self._warp = 0, warp
        self._saved = {name: getattr(warp, name) for name in ("launch", "launch_tiled")}
        for name, launch in self._saved.items():
            setattr(warp, name, self._counted(launch))
        return self

    def _counted(self, launch: Callable) -> Callable:
        def counted(*args: Any, **kwargs: Any) -> Any:
            self.count += 1
            return launch(*args, **kwargs)

        return counted

    def __exit__(self, *exc: object) -> None:
        for name, launch in self._saved.items():
            setattr(self._warp, name, launch)


def torch_ops(call: Callable[[], Any]) -> int:
    """Torch operators ``call`` dispatches (on a GPU, about one kernel launch each)."""
    from torch.utils._python_dispatch import TorchDispatchMode

    class Count(TorchDispatchMode):
        count = 0

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            Count.count += 1
            return func(*args, **(kwargs or {}))

    with Count():
        call()
    return Count.count


def step_breakdown(device: str, n: int, repeats: int) -> dict[str, Any]:
    """Where a training env step's time goes at N simulations, and what it launches.

    Each Warp sequence of the torch face's step (the frame skip's substeps, the sensor
    pass, the autoreset's reset and its observed stages of ``forward``; MuJoCo Warp's whole
    ``forward``, which autoresets ran before, for comparison) is replayed ``repeats``
    times from its graph and timed; the whole face step and a collector step too. Warp
    launches are counted with each sequence launched once from Python, torch operators
    per collector step as the difference of a 2-step and a 1-step rollout.
    """
    import torch

    from qdil.envs.torch_vector import TorchVectorEnv
    from qdil.envs.vector import LocomotionVectorEnv
    from qdil.rl.collect import Collector
    from qdil.rl.networks import VectorizedActor
    from qdil.rl.normalize import RunningMeanStd

    sync = _sync(device)
    env = LocomotionVectorEnv(
        "Walker2d-v5", n, autoreset_mode="SameStep", backend="warp", device=device
    )
    face = TorchVectorEnv(env)
    face.reset(seed=0)
    physics, task = env.physics, env.task
    generator = torch.Generator(device=face.device).manual_seed(0)
    dim = env.single_action_space.shape[0]
    actions = torch.rand((n, dim), generator=generator, device=face.device) * 2 - 1
    for _ in range(face.reset_depth + 2):  # compile and record every graph
        face.step(actions)
    mjw, m, d = physics.mjw, physics.wmodel, physics.wdata
    sequences: dict[str, tuple[tuple, Callable[[], None]]] = {
        "substeps": (("step", task.frame_skip), lambda: physics._substeps(task.frame_skip)),
        "sensors": (("sensors",), physics._sensor_pass),
        "reset": (("reset",), lambda: mjw.reset_data(m, d, reset=physics._reset_mask)),
        "observed": (("observed",), physics._observed_stages),
        "forward": (("forward",), lambda: mjw.forward(m, d)),
    }
    result: dict[str, Any] = {"num_envs": n, "repeats": repeats, "ms": {}, "warp_launches": {}}
    with physics._on_torch_stream():
        for name, (key, launches) in sequences.items():
            physics._launch(key, launches)  # records the graph if not yet recorded
            with LaunchCount() as counter:
                launches()
            result["warp_launches"][name] = counter.count
            sync()
            start = time.perf_counter()
            for _ in range(repeats):
                physics._launch(key, launches)
            sync()
            result["ms"][name] = 1e3 * (time.perf_counter() - start) / repeats
    niter = torch.as_tensor(d.solver_niter.numpy()).double()
    result["solver_iterations"] = {"mean": float(niter.mean()), "max": float(niter.max())}
    sync()
    start = time.perf_counter()
    for _ in range(repeats):
        face.step(actions)
    sync()
    result["ms"]["face_step"] = 1e3 * (time.perf_counter() - start) / repeats
    result["torch_ops"] = {"face_step": torch_ops(lambda: face.step(actions))}

    collector = Collector(TorchVectorEnv(env, reset_depth=face.reset_depth))
    obs_dim = env.single_observation_space.shape[0]
    actor = VectorizedActor(3, obs_dim, dim).to(face.device)
    stats = RunningMeanStd(3, (obs_dim,), device=face.device)
    collector.start(seed=1)

    def collect(steps: int) -> Any:
        return collector.collect(actor, stats, steps, generator, update_stats=False)

    collect(face.reset_depth + 2)
    per_rollout = [torch_ops(lambda t=t: collect(t)) for t in (1, 2)]
    result["torch_ops"]["collect_step"] = per_rollout[1] - per_rollout[0]
    steps = max(repeats, 2)
    sync()
    start = time.perf_counter()
    collect(steps)
    sync()
    result["ms"]["collect_step"] = 1e3 * (time.perf_counter() - start) / steps
    return result


def frame_skip_floor(device: str, sizes: list[int], repeats: int) -> dict[str, float]:
    """ms of one frame skip of Walker2d replayed from its Warp graph, zero actions, per N.

    With a single simulation this is the cost of the kernels themselves (launch latency),
    which no batch size lowers.
    """
    import torch

    from qdil.envs.torch_vector import TorchVectorEnv
    from qdil.envs.vector import LocomotionVectorEnv

    sync, result = _sync(device), {}
    for n in sizes:
        env = LocomotionVectorEnv(
            "Walker2d-v5", n, autoreset_mode="SameStep", backend="warp", device=device
        )
        face = TorchVectorEnv(env)
        face.reset(seed=0)
        zeros = torch.zeros((n, env.single_action_space.shape[0]), device=face.device)
        for _ in range(face.reset_depth + 2):
            face.step(zeros)
        physics = env.physics
        graph = physics._graphs.get(("step", env.task.frame_skip))
        with physics._on_torch_stream():
            sync()
            start = time.perf_counter()
            for _ in range(repeats):
                if graph is None:
                    physics._substeps(env.task.frame_skip)
                else:
                    physics.warp.capture_launch(graph)
            sync()
        result[str(n)] = 1e3 * (time.perf_counter() - start) / repeats
        del face, env
    return result


def rollout_syncs(device: str, overrides: list[str], steps: int | None) -> dict[str, Any]:
    """Host syncs in one training rollout of the recipe's size (CUDA only: torch counts them)."""
    import torch

    from qdil.cli.fit import build, fit_parser, parse_fit
    from qdil.rl.normalize import RunningMeanStd

    with tempfile.TemporaryDirectory() as folder:
        argv = [str(RECIPE), "--env.device", device, "--logging.wandb", "disabled", *overrides]
        config, _, _ = parse_fit(argv)
        config.name = "gpu_check"
        run = build(fit_parser().instantiate(config), "gpu_check", Path(folder), "", resume=False)
        vppo, collector = run.vppo, run.vppo.executor.collector
        steps = steps or vppo.rollout_length
        actor = vppo._actor(vppo.initial_solution(0)[None].repeat(vppo.num_objectives, 0))
        stats = RunningMeanStd(vppo.num_objectives, (vppo.obs_dim,), device=collector.device)
        collector.start(seed=0)
        # the first rollout records the graphs; the second is the one counted
        collector.collect(actor, stats, steps, vppo.generator, update_stats=True)
        counted = None
        cuda = device.startswith("cuda")
        if cuda:
            torch.cuda.synchronize()
            torch.cuda.set_sync_debug_mode("warn")
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                start = time.perf_counter()
                collector.collect(actor, stats, steps, vppo.generator, update_stats=True)
                _sync(device)()
                seconds = time.perf_counter() - start
        finally:
            if cuda:
                torch.cuda.set_sync_debug_mode("default")
        if cuda:
            counted = sum("synchroniz" in str(w.message) for w in caught)
        n = collector.env.num_envs
    return {
        "num_envs": n,
        "steps": steps,
        "syncs": counted,
        "syncs_per_step": None if counted is None else counted / steps,
        "reset_depth": collector.env.reset_depth,
        "env_steps_per_second": n * steps / seconds,
    }


def qd_iterations(device: str, overrides: list[str], iterations: int) -> list[dict[str, float]]:
    """Each iteration's seconds, per phase, of ``qdil fit`` on the GPU recipe."""
    from qdil.cli import main

    here = Path.cwd()
    with tempfile.TemporaryDirectory() as folder:
        os.chdir(folder)
        try:
            argv = ["fit", str(RECIPE), "--env.device", device, *overrides]
            argv += ["--qd.iterations", str(iterations), "--name", "gpu_check"]
            argv += ["--logging.wandb", "disabled", "--logging.progress", "false"]
            main(argv)
            with open(Path(folder) / "runs" / "gpu_check" / "metrics.csv", newline="") as file:
                rows = list(csv.DictReader(file))
        finally:
            os.chdir(here)
    keep = ["iter_seconds", "env_steps", "sps", *(f"{p}_seconds" for p in PHASES)]
    return [
        {key: float(row[f"perf/{key}"]) for key in keep if row.get(f"perf/{key}", "") != ""}
        | {"iteration": int(row["iteration"])}
        for row in rows
    ]


def gpu_tests(timeout: float) -> dict[str, Any]:
    """Outcome of every GPU test (``pytest -m gpu``; they skip where CUDA is missing)."""
    with tempfile.TemporaryDirectory() as folder:
        report = Path(folder) / "junit.xml"
        command = [sys.executable, "-m", "pytest", "-m", "gpu", "-n", "0", "-q", *GPU_TESTS]
        command += [f"--junitxml={report}"]
        start = time.perf_counter()
        done = subprocess.run(
            command, cwd=ROOT, capture_output=True, text=True, timeout=max(timeout, 1)
        )
        outcomes = {}
        for case in ElementTree.parse(report).getroot().iter("testcase"):
            found = [child.tag for child in case if child.tag in ("failure", "error", "skipped")]
            outcomes[f"{case.get('classname')}::{case.get('name')}"] = (
                found[0] if found else "passed"
            )
    return {
        "returncode": done.returncode,
        "seconds": time.perf_counter() - start,
        "outcomes": outcomes,
        "tail": done.stdout[-3000:],
    }


def markdown(result: dict[str, Any]) -> str:
    """The guide's tables from ``result``."""
    info = result.get("machine", {})
    lines = [f"GPU check on {info.get('card', '?')} ({result['command']})", ""]
    if "throughput" in result:
        lines += ["| N | rollout face env-steps/s |", "|---|---|"]
        lines += [f"| {int(n):,} | {sps:,.0f} |" for n, sps in result["throughput"].items()]
        lines.append("")
    if "syncs" in result:
        s = result["syncs"]
        count = "n/a (CPU)" if s["syncs"] is None else f"{s['syncs']} ({s['syncs_per_step']:.3f})"
        sps = s["env_steps_per_second"]
        lines += [
            "| training rollout | steps | host syncs (per step) | env-steps/s |",
            "|---|---|---|---|",
            f"| N = {s['num_envs']:,} | {s['steps']} | {count} | {sps:,.0f} |",
            "",
        ]
    if "breakdown" in result:
        b = result["breakdown"]
        lines += [
            f"| one training step at N = {b['num_envs']:,} | ms | Warp launches | torch ops |",
            "|---|---|---|---|",
        ]
        for name, ms in b["ms"].items():
            launches = b["warp_launches"].get(name, "")
            ops = b["torch_ops"].get(name, "")
            lines.append(f"| {name} | {ms:.2f} | {launches} | {ops} |")
        it = b["solver_iterations"]
        if "floor" in result:
            floor = ", ".join(
                f"{float(ms):.2f} ms at N = {int(n):,}" for n, ms in result["floor"].items()
            )
            lines += ["", f"One frame skip replayed at zero actions: {floor}."]
        lines += [
            "",
            f"Solver iterations per world: mean {it['mean']:.1f}, max {it['max']:.0f}.",
            "",
        ]
    for key, title in (("iterations", "side by side"), ("iterations_in_turns", "in turns")):
        if key not in result:
            continue
        head = ["iteration", "seconds", *PHASES, "env-steps/s"]
        lines += [f"Evaluations {title}:", ""]
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for row in result[key]:
            cells = [str(row["iteration"]), f"{row['iter_seconds']:.1f}"]
            cells += [f"{row.get(f'{p}_seconds', float('nan')):.1f}" for p in PHASES]
            cells.append(f"{row.get('sps', float('nan')):,.0f}")
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    if "tests" in result:
        lines += ["| GPU test | result |", "|---|---|"]
        lines += [f"| `{name}` | {o} |" for name, o in result["tests"]["outcomes"].items()]
        lines.append("")
    for step, error in result.get("errors", {}).items():
        lines.append(f"- {step} failed: {error}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--device", default="cuda", help="cuda (default) or cpu")
    parser.add_argument("--quick", action="store_true", help="scaled down (Warp's CPU device)")
    parser.add_argument("--out", type=Path, default=Path("gpu_check"), help="output folder")
    parser.add_argument("--budget", type=float, default=480.0, help="seconds for all steps")
    parser.add_argument("--skip", default="", help="comma-separated steps to leave out")
    parser.add_argument(
        "--set", default="", help="more `qdil fit` overrides, e.g. --set='--bonus.enabled false'"
    )
    args = parser.parse_args(argv)
    if args.device.startswith("cuda"):
        import torch

        if not torch.cuda.is_available():
            parser.error("--device cuda: torch finds no CUDA device; use --device cpu --quick")
    start = time.perf_counter()
    args.out.mkdir(parents=True, exist_ok=True)
    overrides = (QUICK if args.quick else []) + shlex.split(args.set)
    sizes = [6, 24] if args.quick else [1024, 4096, 16384]
    turns = 3 if args.quick else 3000  # the larger of the two groups: room for one at a time
    command = "python benchmarks/gpu_check.py " + " ".join(argv or sys.argv[1:])
    result: dict[str, Any] = {"command": command.strip(), "device": args.device, "errors": {}}
    steps: dict[str, Callable[[], Any]] = {
        "machine": lambda: machine(args.device),
        "breakdown": lambda: step_breakdown(
            args.device, 6 if args.quick else 3000, 3 if args.quick else 50
        ),
        "floor": lambda: frame_skip_floor(
            args.device, [1, 6] if args.quick else [1, 256, 3000, 16384], 3 if args.quick else 100
        ),
        "throughput": lambda: rollout_throughput(args.device, sizes, 10 if args.quick else 100),
        "syncs": lambda: rollout_syncs(args.device, overrides, 8 if args.quick else None),
        "iterations": lambda: qd_iterations(args.device, overrides, 2),
        # the same iterations with θ_μ and its branches scored one after the other
        "iterations_in_turns": lambda: qd_iterations(
            args.device, [*overrides, "--env.eval_envs", str(turns)], 2
        ),
        "tests": lambda: gpu_tests(args.budget - (time.perf_counter() - start)),
    }
    for name, step in steps.items():
        if name in args.skip.split(","):
            continue
        began = time.perf_counter()
        try:
            result[name] = step()
        except (Exception, SystemExit) as error:  # a finding; the other steps still run
            result["errors"][name] = f"{type(error).__name__}: {error}"
            result.setdefault("tracebacks", {})[name] = traceback.format_exc()
        result.setdefault("seconds", {})[name] = time.perf_counter() - began
        (args.out / "gpu_check.json").write_text(json.dumps(result, indent=1))
        (args.out / "gpu_check.md").write_text(markdown(result))
        print(f"{name}: {result['seconds'][name]:.1f} s", flush=True)
    print(markdown(result))
    return result


if __name__ == "__main__":
    main()
