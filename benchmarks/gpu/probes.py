"""What the GPU check measures below a QD iteration: one env step, its floor, syncs, throughput.

Each probe builds Walker2d-v5 on MuJoCo Warp (``device`` ``cuda`` or ``cpu``), warms up
past kernel compilation and graph recording, and then times; ``benchmarks/gpu_check.py``
runs them and writes their figures.
"""

from __future__ import annotations

import os
import platform
import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

from benchmarks.gpu.code import ROOT, code_version

RECIPE = ROOT / "recipes" / "gpu" / "walker_mcwae.yaml"


def _sync(device: str) -> Callable[[], None]:
    import torch

    return torch.cuda.synchronize if device.startswith("cuda") else lambda: None


def _walker_face(device: str, n: int) -> tuple[Any, Any]:
    """Walker2d-v5 on MuJoCo Warp with N simulations, autoreset on, and its torch face, reset."""
    from qdil.envs.torch_vector import TorchVectorEnv
    from qdil.envs.vector import LocomotionVectorEnv

    env = LocomotionVectorEnv(
        "Walker2d-v5", n, autoreset_mode="SameStep", backend="warp", device=device
    )
    face = TorchVectorEnv(env)
    face.reset(seed=0)
    return env, face


def machine(device: str) -> dict[str, Any]:
    """The card, the host and the versions every figure depends on."""
    import mujoco
    import torch

    from qdil.envs.warp_startup import import_warp

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
        "code": code_version(),
    }


def rollout_throughput(device: str, sizes: list[int], steps: int) -> dict[str, float]:
    """env-steps/s of the rollouts' face, random actions, autoreset on, after a warm-up."""
    import torch

    sync, result = _sync(device), {}
    for n in sizes:
        env, face = _walker_face(device, n)
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
    times from its graph and timed; the whole face step (on CUDA also replayed from one
    CUDA graph, ``TorchVectorEnv.step_graph``) and a collector step too. Warp
    launches are counted with each sequence launched once from Python, torch operators
    per collector step as the difference of a 2-step and a 1-step rollout.
    """
    import torch

    from qdil.envs.torch_vector import TorchVectorEnv
    from qdil.rl.collect import Collector
    from qdil.rl.networks import VectorizedActor
    from qdil.rl.normalize import RunningMeanStd

    sync, cuda = _sync(device), device.startswith("cuda")
    env, face = _walker_face(device, n)
    physics, task = env.physics, env.task
    generator = torch.Generator(device=face.device).manual_seed(0)
    dim = env.single_action_space.shape[0]
    actions = torch.rand((n, dim), generator=generator, device=face.device) * 2 - 1
    for _ in range(face.reset_depth + 2):  # compile and record every graph
        face.step(actions)
    mjw, m, d = physics.mjw, physics.wmodel, physics.wdata
    sequences: dict[str, tuple[tuple, Callable[[], None]]] = {
        "substeps": (("step", task.frame_skip, n), lambda: physics._substeps(task.frame_skip, d)),
        "sensors": (("sensors", n), lambda: physics._sensor_pass(d)),
        "reset": (("reset",), lambda: mjw.reset_data(m, d, reset=physics._reset_mask)),
        "observed": (("observed",), physics._observed_stages),
        "forward": (("forward",), lambda: mjw.forward(m, d)),
    }
    result: dict[str, Any] = {"num_envs": n, "repeats": repeats, "ms": {}, "warp_launches": {}}
    with physics._on_torch_stream():
        for name, (key, launches) in sequences.items():
            physics.graphs.launch(key, launches)  # records the graph if not yet recorded
            with LaunchCount() as counter:
                launches()
            result["warp_launches"][name] = counter.count
            sync()
            start = time.perf_counter()
            for _ in range(repeats):
                physics.graphs.launch(key, launches)
            sync()
            result["ms"][name] = 1e3 * (time.perf_counter() - start) / repeats
    niter = torch.as_tensor(d.solver_niter.numpy()).double()
    result["solver_iterations"] = {"mean": float(niter.mean()), "max": float(niter.max())}
    result["torch_ops"] = {}
    # the face's step as it is and, on CUDA, replayed from one CUDA graph
    for name, graphed in [("face_step", False)] + [("face_step_graphed", True)] * cuda:
        face.step_graph = graphed
        for _ in range(face.reset_depth + 2):  # (re)records the graph, past a top-up
            face.step(actions)
        sync()
        start = time.perf_counter()
        for _ in range(repeats):
            face.step(actions)
        sync()
        result["ms"][name] = 1e3 * (time.perf_counter() - start) / repeats
        result["torch_ops"][name] = torch_ops(lambda: face.step(actions))
    face.step_graph = False

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

    sync, result = _sync(device), {}
    for n in sizes:
        env, face = _walker_face(device, n)
        zeros = torch.zeros((n, env.single_action_space.shape[0]), device=face.device)
        for _ in range(face.reset_depth + 2):
            face.step(zeros)
        physics = env.physics
        graph = physics.graphs.recorded.get(("step", env.task.frame_skip, physics.num_sims))
        with physics._on_torch_stream():
            sync()
            start = time.perf_counter()
            for _ in range(repeats):
                if graph is None:
                    physics._substeps(env.task.frame_skip, physics.wdata)
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
    from qdil.rl.networks import VectorizedActor
    from qdil.rl.normalize import RunningMeanStd

    with tempfile.TemporaryDirectory() as folder:
        argv = [str(RECIPE), "--env.device", device, "--logging.wandb", "disabled", *overrides]
        config, _, _ = parse_fit(argv)
        config.name = "gpu_check"
        run = build(fit_parser().instantiate(config), "gpu_check", Path(folder), "", resume=False)
        vppo, collector = run.estimator, run.executor.collector
        steps = steps or vppo.rollout_length
        dims = (vppo.obs_dim, vppo.action_dim, vppo.actor_hidden)
        theta = VectorizedActor.initial_solution(*dims, 0)
        actor = vppo._actor(theta[None].repeat(vppo.num_objectives, 0))
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


def _largest_differences(a: dict[str, Any], b: dict[str, Any]) -> dict[str, float]:
    """Largest absolute difference of each tensor field of two rollouts (NaN equal to NaN)."""
    return {
        key: float((a[key].double() - b[key].double()).abs().nan_to_num(0.0).max())
        for key in a
        if a[key].numel()
    }


def repeatability(device: str, quick: bool) -> dict[str, Any]:
    """How far the same computation lands from itself: a run-to-run test of the engine.

    The training rollout of ``tests/test_gpu.py`` (48 simulations, 12-step episodes, 40 steps)
    played twice eagerly and once with each step replayed from a CUDA graph, with MuJoCo
    Warp's default kernels and with its deterministic ones (``env.deterministic``), and its
    evaluation (3 policies, 32 episodes each, up to 60 steps) played twice narrowed to the
    running episodes and twice not: the largest difference of every field between the pairs.
    On Warp's CPU device all are 0; on CUDA MuJoCo Warp's atomics order contacts and sums
    differently from run to run (docs/guides/gpu.md).
    """
    import numpy as np
    import torch

    from qdil.envs.torch_vector import TorchVectorEnv
    from qdil.envs.vector import LocomotionVectorEnv
    from qdil.rl.collect import Collector
    from qdil.rl.episodes import EvaluationGroup, evaluate_groups
    from qdil.rl.networks import VectorizedActor
    from qdil.rl.normalize import RunningMeanStd

    def rollout(graphed: bool, deterministic: bool = False) -> dict[str, Any]:
        env = LocomotionVectorEnv(
            "Walker2d-v5", 12 if quick else 48, max_episode_steps=12,
            autoreset_mode="SameStep", backend="warp", device=device,
            deterministic=deterministic,
        )  # fmt: skip
        face = TorchVectorEnv(env)
        face.step_graph = graphed
        torch.manual_seed(0)
        actor = VectorizedActor(3, 17, 6).to(device)
        stats = RunningMeanStd(3, (17,), device=device)
        generator = torch.Generator(device=device).manual_seed(3)
        collector = Collector(face)
        collector.start(seed=4)
        data, extras = collector.collect(actor, stats, 40, generator, update_stats=True)
        fields = {**vars(data), **vars(extras)}
        return {k: t.cpu() for k, t in fields.items() if torch.is_tensor(t)}

    actor = VectorizedActor(3, 17, 6)
    solutions = np.stack([actor.initial_solution(17, 6, seed=s) for s in range(3)])
    actor.set_solutions(solutions * np.array([3.0, 30.0, 10.0])[:, None])
    actor, stats = actor.to(device), RunningMeanStd(3, (17,), device=device)

    def evaluation(narrow: bool) -> dict[str, Any]:
        env = LocomotionVectorEnv(
            "Walker2d-v5", 12 if quick else 96, max_episode_steps=60,
            autoreset_mode="Disabled", backend="warp", device=device,
        )  # fmt: skip
        face = TorchVectorEnv(env)
        if not narrow:
            face.narrow = lambda mask: None
        generator = torch.Generator(device=device).manual_seed(2)
        group = EvaluationGroup(actor, stats, 4 if quick else 32, 9, generator)
        (scores,) = evaluate_groups(face, [group], sync_every=4)
        fields = ("lengths", "true_objective", "measures")
        return {key: torch.as_tensor(np.asarray(getattr(scores, key))) for key in fields}

    eager, ordered = rollout(False), rollout(False, deterministic=True)
    narrowed, wide = evaluation(True), evaluation(False)
    return {
        "rollout_eager_vs_eager": _largest_differences(eager, rollout(False)),
        "rollout_graphed_vs_eager": _largest_differences(rollout(True), eager),
        "rollout_deterministic_eager_vs_eager": _largest_differences(
            ordered, rollout(False, deterministic=True)
        ),
        "rollout_deterministic_graphed_vs_eager": _largest_differences(
            rollout(True, deterministic=True), ordered
        ),
        "evaluation_narrowed_vs_narrowed": _largest_differences(narrowed, evaluation(True)),
        "evaluation_wide_vs_wide": _largest_differences(wide, evaluation(False)),
        "evaluation_narrowed_vs_wide": _largest_differences(narrowed, wide),
    }


def repeatability_table(pairs: dict[str, dict[str, float]]) -> list[str]:
    """The Markdown lines of :func:`repeatability`'s largest differences, a row per pair."""
    fields = ["obs", "rewards", "dones", "contacts", "lengths", "true_objective", "measures"]
    lines = ["Largest difference between two plays of the same computation:", ""]
    lines += ["| pair | " + " | ".join(fields) + " |", "|" + "---|" * (len(fields) + 1)]
    for pair, diffs in pairs.items():
        cells = [f"{diffs[f]:.2g}" if f in diffs else "" for f in fields]
        lines.append(f"| {pair} | " + " | ".join(cells) + " |")
    return [*lines, ""]
