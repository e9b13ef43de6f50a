"""The CUDA path: a short fit on the GPU, placement, and no per-step host sync.

Skipped without CUDA. On a machine with an NVIDIA GPU, a CUDA build of torch and the warp
extra, one command runs them (docs/guides/gpu.md):

    pytest -m gpu -n 0 tests/test_gpu.py tests/envs/test_warp_backend.py

On an NVIDIA H200 (2026-11-26) the sync count read 15 in 64 steps: three reset-queue top-ups
of five syncs each (a read and four pageable copies). With the copies pinned, an H100 read
one per top-up and all of these passed (docs/guides/gpu.md; `benchmarks/gpu_check.py`).
"""

from __future__ import annotations

import csv
import warnings
from pathlib import Path

import pytest
import torch
from run_devices import build, off_device

pytestmark = [
    pytest.mark.gpu,
    pytest.mark.skipif(
        not torch.cuda.is_available(), reason="needs a CUDA GPU and a CUDA build of torch"
    ),
]
pytest.importorskip("mujoco_warp", reason="the warp extra is not installed")

from qdil.cli import main  # noqa: E402
from qdil.envs.torch_vector import TorchVectorEnv  # noqa: E402
from qdil.rl.networks import VectorizedActor  # noqa: E402
from qdil.rl.normalize import RunningMeanStd  # noqa: E402
from tests.commands import SMOKE  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
IL = ROOT / "recipes" / "smoke" / "walker_il.yaml"
ON_GPU = ("--env.backend", "warp", "--env.device", "cuda")


def test_a_short_fit_runs_on_cuda(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    main(["fit", str(SMOKE), *ON_GPU, "--name", "gpu"])
    with open(tmp_path / "runs" / "gpu" / "metrics.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    assert [row["iteration"] for row in rows] == ["1", "2", "3"]
    assert float(rows[-1]["qd/num_elites"]) >= 1


def test_every_tensor_of_a_run_is_on_the_gpu(tmp_path: Path, walker_demos) -> None:
    run = build(
        IL,
        tmp_path / "run",
        *ON_GPU,
        "--demos.path",
        str(walker_demos),
        "--bonus.enabled",
        "true",
    )
    assert off_device(run, torch.device("cuda")) == []
    assert run.fabric.device.type == "cuda"
    assert run.env.physics.torch_exported.device.type == "cuda"
    assert isinstance(run.executor.collector.env, TorchVectorEnv)


def test_a_rollout_does_not_sync_with_the_host_per_step(tmp_path: Path) -> None:
    run = build(SMOKE, tmp_path / "run", *ON_GPU)
    vppo, collector = run.estimator, run.executor.collector
    theta = VectorizedActor.initial_solution(vppo.obs_dim, vppo.action_dim, vppo.actor_hidden, 0)
    actor = vppo._actor(theta[None].repeat(vppo.num_objectives, 0))
    stats = RunningMeanStd(vppo.num_objectives, (vppo.obs_dim,), device="cuda")
    collector.start(seed=0)
    steps, depth = 64, collector.env.reset_depth
    torch.cuda.synchronize()
    torch.cuda.set_sync_debug_mode("warn")  # torch warns at every synchronising call
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            rollout, extras = collector.collect(
                actor, stats, steps, vppo.generator, update_stats=True
            )
    finally:
        torch.cuda.set_sync_debug_mode("default")
    # every field the rollout hands on lives on the GPU (a CPU `valid` mask once broke the
    # bonus's visit counts there, and no CPU test can see it)
    fields = {**vars(rollout), **vars(extras)}
    assert [k for k, t in fields.items() if torch.is_tensor(t) and not t.is_cuda] == []
    syncs = [w for w in caught if "synchroniz" in str(w.message)]
    # the reset-noise queues are topped up every `depth` steps; nothing else syncs
    assert len(syncs) <= steps // depth, [str(w.message) for w in syncs]


def test_a_narrowed_evaluation_agrees_with_a_wide_one_on_cuda(monkeypatch) -> None:
    """Ended episodes leave the batch on the GPU too, and the scores stay.

    On Warp's CPU device narrowing changes no bit (``tests/envs/test_warp_narrow.py``). On
    CUDA MuJoCo Warp is not repeatable bit for bit (its atomics order contacts and sums
    differently from run to run), so the same evaluation played twice differs by itself:
    returns by up to 1e-4 on an H200 (2026-11-27), narrowed or not, and once an episode by
    two steps. The bounds below are ten times that.
    """
    import numpy as np

    from qdil.envs.vector import LocomotionVectorEnv
    from qdil.rl.episodes import EvaluationGroup, evaluate_groups
    from qdil.rl.networks import VectorizedActor

    actor = VectorizedActor(3, 17, 6)
    solutions = np.stack([actor.initial_solution(17, 6, seed=s) for s in range(3)])
    actor.set_solutions(solutions * np.array([3.0, 30.0, 10.0])[:, None])
    actor, stats = actor.to("cuda"), RunningMeanStd(3, (17,), device="cuda")

    def evaluate() -> tuple[list, int]:
        env = LocomotionVectorEnv(
            "Walker2d-v5", 96, max_episode_steps=60, autoreset_mode="Disabled",
            backend="warp", device="cuda",
        )  # fmt: skip
        face = TorchVectorEnv(env)
        generator = torch.Generator(device="cuda").manual_seed(2)
        group = EvaluationGroup(actor, stats, 32, 9, generator)
        return evaluate_groups(face, [group], sync_every=4), env.physics.world_steps

    (narrowed,), narrowed_steps = evaluate()
    monkeypatch.setattr(TorchVectorEnv, "narrow", lambda self, mask: None)
    (wide,), wide_steps = evaluate()
    # mean episode lengths of the 3 policies (32 episodes each); 0.0625 is 2 steps in all
    np.testing.assert_allclose(narrowed.lengths, wide.lengths, rtol=0, atol=0.625)
    np.testing.assert_allclose(narrowed.true_objective, wide.true_objective, rtol=0, atol=1e-3)
    np.testing.assert_allclose(narrowed.measures, wide.measures, rtol=0, atol=0.02)
    assert narrowed_steps < wide_steps


def _rollout(graphed: bool, deterministic: bool = False) -> tuple[dict, object, TorchVectorEnv]:
    """A 40-step training rollout of 48 simulations with 12-step episodes on CUDA: its
    fields on the host, the environment and its face. The autoresets and the reset-queue
    top-ups (every 16 steps, outside any graph) are part of it."""
    from qdil.envs.vector import LocomotionVectorEnv
    from qdil.rl.collect import Collector
    from qdil.rl.networks import VectorizedActor

    env = LocomotionVectorEnv(
        "Walker2d-v5", 48, max_episode_steps=12, autoreset_mode="SameStep",
        backend="warp", device="cuda", deterministic=deterministic,
    )  # fmt: skip
    face = TorchVectorEnv(env)
    face.step_graph = graphed
    collector = Collector(face)
    actor = VectorizedActor(3, 17, 6).to("cuda")  # zero weights: actions are the noise
    stats = RunningMeanStd(3, (17,), device="cuda")
    generator = torch.Generator(device="cuda").manual_seed(3)
    collector.start(seed=4)
    data, extras = collector.collect(actor, stats, 40, generator, update_stats=True)
    fields = {**vars(data), **vars(extras)}
    return {k: t.cpu() for k, t in fields.items() if torch.is_tensor(t)}, env, face


def test_a_training_step_replayed_from_a_cuda_graph_agrees_with_the_eager_step() -> None:
    """The device face's training step recorded in one CUDA graph (``StepGraph``).

    MuJoCo Warp on CUDA is not repeatable bit for bit: two eager rollouts differed by up to
    8.3e-5 in the observations on an H200 (2026-11-27), the graphed one from an eager one
    by 7.8e-5. Every event (an episode's end, a foot's contact) must be the same, and the
    values within ten times that spread.
    """
    eager, eager_env, _ = _rollout(graphed=False)
    graphed, graphed_env, face = _rollout(graphed=True)
    assert face._graph is not None and face._graph._graph is not None  # replayed
    assert eager.keys() == graphed.keys()
    for key in eager:
        exact = eager[key].dtype == torch.bool or key == "actions"  # events; noise alone
        atol = 0.0 if exact else 1e-3
        torch.testing.assert_close(graphed[key], eager[key], rtol=0, atol=atol, msg=key)
    assert graphed_env.physics.world_steps == eager_env.physics.world_steps == 40 * 48


def test_deterministic_kernels_repeat_a_rollout_bit_for_bit_on_cuda() -> None:
    """``env.deterministic``: the same rollout twice, and once replayed from a CUDA graph,
    give the same bits (MuJoCo Warp's sorted contacts and ordered sums)."""
    first, _, _ = _rollout(graphed=False, deterministic=True)
    again, _, _ = _rollout(graphed=False, deterministic=True)
    graphed, _, face = _rollout(graphed=True, deterministic=True)
    assert face._graph is not None and face._graph._graph is not None  # replayed
    for key in first:
        torch.testing.assert_close(again[key], first[key], rtol=0, atol=0, msg=key)
        torch.testing.assert_close(graphed[key], first[key], rtol=0, atol=0, msg=key)
