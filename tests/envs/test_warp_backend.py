"""The MuJoCo Warp backend agrees with the C backend (Warp's CPU device, a few worlds).

Tolerances (float32 Warp against float64 C, one env step from the same state, random
actions, contacts included; absolute, the states' scale is ~1–10): Walker2d, HalfCheetah,
Hopper and Humanoid-v5-newton positions within 1e-5, velocities within 2e-3, rewards within
1e-3. Ant, whose 10 ms RK4 step with up to four legs on the floor amplifies float32
rounding through the contact solver, only within 0.05, 2.0 and 0.5 at worst, 2e-3, 0.2
and 0.05 in the median (measured: 0.016, 0.98 and 0.20 at worst over 25 steps). Foot
contacts and terminations are identical on every task.
The first Warp step compiles kernels (tens of seconds, cached on disk in Warp's kernel
cache), so the environments are built once per module, and the smoke ``qdil fit`` on the
Warp backend lives here too: one test worker compiles, the other tests reuse its kernels.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import torch

pytest.importorskip("mujoco_warp", reason="the warp extra is not installed")

from qdil.cli import main
from qdil.envs.vector import LocomotionVectorEnv
from tests.commands import SMOKE

TASKS = ["Walker2d-v5", "HalfCheetah-v5", "Hopper-v5", "Ant-v5", "Humanoid-v5-newton"]
NUM = 3
# (qpos, qvel, reward) tolerances: at worst, and in the median over the steps
TIGHT = {"worst": (1e-5, 2e-3, 1e-3), "median": (1e-5, 2e-3, 1e-3)}
TOLERANCES = {"Ant-v5": {"worst": (0.05, 2.0, 0.5), "median": (2e-3, 0.2, 0.05)}}


@pytest.fixture(scope="module", params=TASKS)
def pair(request) -> tuple[LocomotionVectorEnv, LocomotionVectorEnv]:
    """(C env, Warp env) of one task, autoreset disabled."""
    make = dict(num_envs=NUM, autoreset_mode="Disabled")
    return (
        LocomotionVectorEnv(request.param, **make),
        LocomotionVectorEnv(request.param, backend="warp", device="cpu", **make),
    )


def test_one_step_agrees_with_the_c_backend(pair) -> None:
    c_env, warp_env = pair
    c_env.reset(seed=3)
    warp_env.reset(seed=3)
    rng = np.random.default_rng(0)
    low, high = c_env.single_action_space.low, c_env.single_action_space.high
    contacts_seen = 0.0
    errors = []
    for _ in range(25):
        # the Warp simulations start each step from the C simulations' state
        ids = np.arange(NUM)
        warp_env.physics.reset(ids, c_env.physics.view("qpos"), c_env.physics.view("qvel"))
        actions = rng.uniform(low, high, (NUM, low.size))
        _, c_reward, c_term, _, c_info = c_env.step(actions)
        _, w_reward, w_term, _, w_info = warp_env.step(actions)
        errors.append(
            [
                np.abs(c_env.physics.view(field) - warp_env.physics.view(field)).max()
                for field in ("qpos", "qvel")
            ]
            + [np.abs(w_reward - c_reward).max()]
        )
        np.testing.assert_array_equal(w_info["foot_contact"], c_info["foot_contact"])
        np.testing.assert_array_equal(w_term, c_term)
        contacts_seen += c_info["foot_contact"].sum()
        if c_term.any():
            c_env.reset(options={"reset_mask": c_term})
            warp_env.reset(options={"reset_mask": c_term})
    tolerance = TOLERANCES.get(c_env.task.gym_id, TIGHT)
    for statistic, reduce in (("worst", np.max), ("median", np.median)):
        measured = reduce(np.array(errors), axis=0)
        for what, value, atol in zip(
            ("qpos", "qvel", "reward"), measured, tolerance[statistic], strict=True
        ):
            assert value <= atol, f"{what} ({statistic}): {value:.3g} > {atol}"
    if c_env.task.gym_id != "Humanoid-v5-newton":  # its feet leave the floor at reset
        assert contacts_seen > 0  # the comparison covered steps with the feet on the floor


def test_reset_distribution_is_the_c_backends(pair) -> None:
    c_env, warp_env = pair
    for seed in (0, 11):
        c_obs, c_info = c_env.reset(seed=seed)
        w_obs, w_info = warp_env.reset(seed=seed)
        # the same numpy draws, written and forwarded in float32
        np.testing.assert_allclose(w_obs, c_obs, rtol=1e-5, atol=1e-6)
        np.testing.assert_array_equal(w_info["foot_contact"], c_info["foot_contact"])


def test_masked_out_worlds_keep_their_state(pair) -> None:
    _, warp_env = pair
    warp_env.reset(seed=5)
    before = warp_env.physics.view("qpos").copy()
    mask = np.array([True, False, True])
    warp_env.step(np.zeros((NUM, warp_env.single_action_space.shape[0])), mask=mask)
    after = warp_env.physics.view("qpos")
    np.testing.assert_array_equal(after[1], before[1])
    assert not np.array_equal(after[0], before[0])
    # the Warp state of the left-out world is its old state too, not only the host copy
    torch_qpos = warp_env.physics._qpos.cpu().double().numpy()
    np.testing.assert_allclose(torch_qpos[1], before[1], atol=1e-6)


def test_bad_backend_or_device_is_refused_with_the_setting_named() -> None:
    """The environment's constructor checks the pair once (qdil.devices.run_device)."""
    with pytest.raises(ValueError, match=r"env\.backend"):
        LocomotionVectorEnv("Walker2d-v5", 1, backend="brax", device="cpu")
    with pytest.raises(ValueError, match=r"env\.device"):
        LocomotionVectorEnv("Walker2d-v5", 1, backend="mujoco", device="cuda")
    with pytest.raises(ValueError, match=r"env\.device"):
        LocomotionVectorEnv("Walker2d-v5", 1, backend="warp", device="tpu")


def test_humanoid_needs_the_newton_variant_on_warp() -> None:
    with pytest.raises(ValueError, match="Humanoid-v5-newton"):
        LocomotionVectorEnv("Humanoid-v5", 1, backend="warp")


def test_fit_runs_on_the_warp_backend(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    main(["fit", str(SMOKE), "--env.backend", "warp", "--env.device", "cpu", "--name", "warp"])
    run_dir = tmp_path / "runs" / "warp"
    with open(run_dir / "metrics.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    assert [row["iteration"] for row in rows] == ["1", "2", "3"]
    assert float(rows[-1]["qd/num_elites"]) >= 1
    assert "backend: warp" in (run_dir / "config.yaml").read_text()


def test_search_policy_and_branches_scored_side_by_side_change_no_bit(
    tmp_path, monkeypatch
) -> None:
    """A Warp run scores θ_μ and its branches in one batch; one after the other is the same.

    ``env.eval_envs`` below their sum makes the device executor play them in turn; the
    smoke recipe samples its evaluation actions (each group's own noise).
    """
    monkeypatch.chdir(tmp_path)
    archives = []
    for name, extra in (("batch", []), ("turns", ["--env.eval_envs", "4"])):
        main(["fit", str(SMOKE), "--env.backend", "warp", "--env.device", "cpu",
              "--qd.iterations", "2", "--name", name, *extra])  # fmt: skip
        with open(tmp_path / "runs" / name / "metrics.csv", newline="") as file:
            rows = [
                {k: v for k, v in row.items() if not k.startswith("perf/")}
                for row in csv.DictReader(file)
            ]
        archives.append(rows)
    assert archives[0] == archives[1]


def test_a_gpu_device_without_cuda_is_refused_naming_the_setting(tmp_path, monkeypatch) -> None:
    import warp

    if warp.is_cuda_available():
        pytest.skip("this machine has CUDA; the refusal is for machines without it")
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as error:
        main(["fit", str(SMOKE), "--env.backend", "warp", "--env.device", "cuda"])
    assert "env.device" in str(error.value)


def test_one_step_agrees_on_a_gpu() -> None:
    """The CUDA path: run on a GPU machine with `pytest tests/envs/test_warp_backend.py`."""
    import warp

    if not warp.is_cuda_available():
        pytest.skip("no CUDA device: the GPU path runs on a machine with an NVIDIA GPU")
    make = dict(num_envs=NUM, autoreset_mode="Disabled")
    c_env = LocomotionVectorEnv("Walker2d-v5", **make)
    gpu_env = LocomotionVectorEnv("Walker2d-v5", backend="warp", device="cuda", **make)
    c_env.reset(seed=3)
    gpu_env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(10):
        gpu_env.physics.reset(
            np.arange(NUM), c_env.physics.view("qpos"), c_env.physics.view("qvel")
        )
        actions = rng.uniform(-1, 1, (NUM, c_env.single_action_space.shape[0]))
        _, c_reward, _, _, c_info = c_env.step(actions)
        _, g_reward, _, _, g_info = gpu_env.step(actions)
        assert np.abs(c_env.physics.view("qpos") - gpu_env.physics.view("qpos")).max() <= 1e-5
        np.testing.assert_allclose(g_reward, c_reward, atol=1e-3)
        np.testing.assert_array_equal(g_info["foot_contact"], c_info["foot_contact"])
    assert gpu_env.physics.torch_exported.device.type == "cuda"


CUDA = pytest.param(
    "cuda",
    marks=[
        pytest.mark.gpu,
        pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU"),
    ],
)


@pytest.mark.parametrize("device", ["cpu", CUDA])
@pytest.mark.parametrize("mode", ["SameStep", "Disabled"])
def test_graph_replays_equal_launches_from_python(mode: str, device: str) -> None:
    """Steps, sensor passes, resets and forwards replayed from Warp graphs change no bit.

    Short episodes make the autoresets (``SameStep``) and the masked steps of finished
    simulations (``Disabled``) run from graphs too.
    """
    make = dict(num_envs=NUM, max_episode_steps=4, autoreset_mode=mode, backend="warp")
    launched = LocomotionVectorEnv("Walker2d-v5", device=device, **make)
    launched.physics.graphs.enabled = False
    replayed = LocomotionVectorEnv("Walker2d-v5", device=device, **make)
    first = [launched.reset(seed=5), replayed.reset(seed=5)]
    np.testing.assert_array_equal(first[0][0], first[1][0])
    rng = np.random.default_rng(1)
    low, high = launched.single_action_space.low, launched.single_action_space.high
    alive = np.ones(NUM, dtype=bool)
    for t in range(10):
        actions = rng.uniform(low, high, (NUM, low.size))
        mask = None if mode == "SameStep" else alive.copy()
        a, b = launched.step(actions, mask=mask), replayed.step(actions, mask=mask)
        for x, y in zip(a[:4], b[:4], strict=True):
            np.testing.assert_array_equal(x, y, err_msg=f"step {t}")
        np.testing.assert_array_equal(a[4]["foot_contact"], b[4]["foot_contact"])
        if mode == "Disabled":  # finished simulations sit out; when all have, start again
            alive &= ~(a[2] | a[3])
            if not alive.any():
                launched.reset(seed=6 + t), replayed.reset(seed=6 + t)
                alive[:] = True
    assert launched.physics.graphs.recorded == {}
    graphs = replayed.physics.graphs.recorded
    recorded = {key[0] for key, graph in graphs.items() if graph is not None}
    assert recorded >= {"step", "sensors", "reset"}


def test_deterministic_kernels_are_asked_for_and_agree_with_the_default_ones() -> None:
    """``env.deterministic``: MuJoCo Warp's deterministic kernels (sorted contacts, ordered
    constraint rows and sums). On Warp's CPU device both kinds repeat; they agree within
    float32 rounding over 30 steps of a walker whose feet touch the floor."""
    mjw = pytest.importorskip("mujoco_warp")
    make = dict(num_envs=NUM, autoreset_mode="Disabled", backend="warp", device="cpu")
    default = LocomotionVectorEnv("Walker2d-v5", **make)
    ordered = LocomotionVectorEnv("Walker2d-v5", deterministic=True, **make)
    assert default.physics.wmodel.opt.deterministic == mjw.DeterminismType.NONE
    assert ordered.physics.wmodel.opt.deterministic == mjw.DeterminismType.ALL
    assert ordered.factory.keywords["deterministic"] is True  # remote shards build it too
    default.reset(seed=5)
    ordered.reset(seed=5)
    rng = np.random.default_rng(1)
    contacts = 0.0
    for _ in range(30):
        actions = rng.uniform(-1, 1, (NUM, 6))
        _, _, ended, _, info = default.step(actions)
        _, _, ordered_ended, _, ordered_info = ordered.step(actions)
        np.testing.assert_array_equal(ordered_info["foot_contact"], info["foot_contact"])
        np.testing.assert_array_equal(ordered_ended, ended)
        contacts += info["foot_contact"].sum()
        if ended.any():
            default.reset(options={"reset_mask": ended})
            ordered.reset(options={"reset_mask": ended})
    assert contacts > 0  # the contact sort had contacts to order
    for field in ("qpos", "qvel"):
        np.testing.assert_allclose(
            ordered.physics.view(field), default.physics.view(field), rtol=0, atol=1e-4
        )
