"""env.device places the whole run, and settings that would split it are refused by name.

On this CPU the placement check passes trivially once it finds the tensors; its negative
control shows it would catch a stray one. ``tests/test_gpu.py`` runs the same check on CUDA.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from run_devices import build, off_device, run_tensors

from qdil.cli import main
from qdil.config import PolicyConfig
from qdil.devices import fabric_settings, run_device
from qdil.envs.vector import LocomotionVectorEnv
from qdil.executors.local import LocalExecutor
from qdil.qd.vppo import VPPO
from tests.commands import SMOKE

ROOT = Path(__file__).resolve().parents[1]
IL = ROOT / "recipes" / "smoke" / "walker_il.yaml"


def test_cuda_on_the_mujoco_backend_is_refused_naming_the_settings() -> None:
    with pytest.raises(ValueError, match=r"env\.device: 'cuda' with env\.backend: mujoco"):
        run_device("mujoco", "cuda")


def test_a_malformed_device_is_refused() -> None:
    with pytest.raises(ValueError, match=r"env\.device must be"):
        run_device("warp", "gpu0")


@pytest.mark.skipif(torch.cuda.is_available(), reason="the refusal is for machines without CUDA")
def test_cuda_without_a_cuda_torch_is_refused() -> None:
    with pytest.raises(ValueError, match=r"env\.device: 'cuda'.*torch finds no CUDA device"):
        run_device("warp", "cuda")


def test_a_missing_gpu_index_is_refused(monkeypatch) -> None:
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    with pytest.raises(ValueError, match=r"env\.device: 'cuda:3'.*1 CUDA device"):
        run_device("warp", "cuda:3")
    assert run_device("warp", "cuda:0") == torch.device("cuda:0")
    assert fabric_settings(torch.device("cuda:0")) == {"accelerator": "cuda", "devices": [0]}


def test_fit_refuses_cuda_on_the_mujoco_backend_before_building(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as error:
        main(["fit", str(SMOKE), "--env.device", "cuda"])
    assert "env.device" in str(error.value) and "env.backend: warp" in str(error.value)


def test_policies_on_another_device_than_the_physics_are_refused() -> None:
    """VPPO takes the physics' device; environments on two devices are refused."""
    train = LocomotionVectorEnv("Walker2d-v5", 3, autoreset_mode="SameStep")
    evaluation = LocomotionVectorEnv("Walker2d-v5", 3, autoreset_mode="Disabled")
    executor = LocalExecutor()
    executor.setup(train, evaluation, 10.0)
    algo = VPPO()
    algo.setup(train, executor, PolicyConfig(), torch.Generator().manual_seed(0), 0)
    assert algo.device == train.device == torch.device("cpu")
    evaluation.device = torch.device("meta")
    with pytest.raises(ValueError, match=r"env\.device: the training physics steps on cpu"):
        LocalExecutor().setup(train, evaluation, 10.0)


def test_every_tensor_of_a_run_is_on_its_device(tmp_path, walker_demos) -> None:
    run = build(IL, tmp_path / "run", "--demos.path", str(walker_demos), "--bonus.enabled", "true")
    tensors = run_tensors(run)
    # the walk found the critics, the reward model, the bonus counts and the expert batch
    assert any(name.startswith("reward.") and "counts" in name for name in tensors)
    assert any(name.startswith("expert.") for name in tensors)
    assert any(name.startswith("walk_critic.") for name in tensors)
    assert off_device(run, torch.device("cpu")) == []
    # negative control: a stray tensor is reported by name
    run.estimator.walk_returns = run.estimator.walk_returns.to("meta")
    assert off_device(run, torch.device("cpu")) == [
        "walk_returns.mean on meta",
        "walk_returns.var on meta",
        "walk_returns.count on meta",
    ]


def test_a_recipe_on_a_device_backend_steps_through_the_torch_face(tmp_path) -> None:
    """The recipe's default executor (in this process) picks the face that fits the physics.

    Regression: ``qdil fit --env.backend warp --env.device cuda`` stepped the numpy face
    with policies on the GPU and failed at the first action (first run on an H200).
    """
    pytest.importorskip("mujoco_warp", reason="the warp extra is not installed")
    from qdil.envs.faces import HostFace
    from qdil.envs.torch_vector import TorchVectorEnv

    on_warp = build(SMOKE, tmp_path / "warp", "--env.backend", "warp")
    assert isinstance(on_warp.executor.collector.env, TorchVectorEnv)
    assert isinstance(on_warp.executor.eval_face, TorchVectorEnv)
    on_c = build(SMOKE, tmp_path / "c")
    assert isinstance(on_c.executor.collector.env, HostFace)
    assert isinstance(on_c.executor.eval_face, HostFace)
