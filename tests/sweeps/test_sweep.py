"""``qdil sweep``: trials equal plain ``qdil fit`` runs, a killed sweep continues to the same
end, a bad override stops it before anything starts, and a crashed trial stops no other."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import time
from pathlib import Path

import pytest

pytest.importorskip("ray.tune")

import ray

from qdil.cli import main
from tests.cli.test_reproducible_runs import archives, metrics, same_archives
from tests.commands import ROOT, SMOKE, qdil, qdil_here, start_qdil

IL = ROOT / "recipes" / "smoke" / "walker_il.yaml"
SEEDS = ("0", "1")  # the kill test needs two trials: one killed, and another beside it


@pytest.fixture(scope="module")
def plain(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``qdil fit`` of the smoke recipe with each seed, as a user runs them one by one."""
    root = tmp_path_factory.mktemp("plain")
    for seed in SEEDS:
        qdil_here(["fit", str(SMOKE), "--seed", seed], root)
    return root / "runs"


@pytest.fixture
def one_ray() -> None:
    """A local Ray for in-process sweeps (2 CPUs: two trials at once), started once."""
    if not ray.is_initialized():
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)


@pytest.fixture(scope="module", autouse=True)
def _ray_down():
    yield
    if ray.is_initialized():
        ray.shutdown()


def scores(run: Path) -> dict:
    """A run's ``eval.json`` without what names the run and the machine."""
    summary = json.loads((run / "eval.json").read_text())
    return {k: v for k, v in summary.items() if k not in ("run", "provenance")}


def same_runs(a: Path, b: Path) -> bool:
    return metrics(a) == metrics(b) and same_archives(archives(a), archives(b))


def test_a_trial_with_the_ray_executor_joins_the_sweeps_cluster(one_ray, plain, tmp_path):
    """Its ``qdil fit`` (executor address null) runs its workers on the sweep's own Ray."""
    root = tmp_path / "runs"
    executor = ["--executor", "qdil.executors.RayExecutor", "--executor.init_args.num_workers", "1"]
    main(["sweep", str(SMOKE), "--seeds", "0", "--root", str(root), "--episodes", "0", *executor])
    assert same_runs(root / "walker_true-seed0", plain / "walker_true-seed0")
    log = (root / ".locks" / "walker_true-seed0.log").read_text()
    address = ray.get_runtime_context().gcs_address
    assert f"Connecting to existing Ray cluster at address: {address}" in log


def test_a_bad_override_stops_the_sweep_before_anything_starts(tmp_path: Path) -> None:
    root = tmp_path / "runs"
    with pytest.raises(SystemExit, match="itrations"):
        main(["sweep", str(SMOKE), "--seeds", "0", "--qd.itrations", "5", "--root", str(root)])
    assert not root.exists()


def test_a_crashed_trial_stops_no_other(one_ray, plain, tmp_path, capsys) -> None:
    root = tmp_path / "runs"
    broken = tmp_path / "broken.npz"  # read when the imitation run starts, not before
    broken.write_bytes(b"not an npz file")
    command = ["sweep", str(SMOKE), str(IL), "--seeds", "0", "--root", str(root)]
    with pytest.raises(SystemExit, match="1 of 2 trials failed"):
        main([*command, "--episodes", "0", "--demos.path", str(broken)])
    (true_run,) = root.glob("walker_true-*-seed0")  # named with the options' hash
    assert same_runs(true_run, plain / "walker_true-seed0")
    out, said = capsys.readouterr()
    assert "FAILED walker_il-" in said and "broken.npz" in said
    # qdil's table and one line per failure; Tune's banner and the traceback stay out
    assert "Configuration for experiment" not in out + said
    assert "Traceback" not in out + said


def test_a_missing_demonstration_file_stops_the_sweep_before_anything_starts(tmp_path) -> None:
    root = tmp_path / "runs"
    command = ["sweep", str(IL), "--seeds", "0", "--root", str(root)]
    with pytest.raises(SystemExit, match=r"no-such\.npz: no such file"):
        main([*command, "--demos.path", str(tmp_path / "no-such.npz")])
    assert not root.exists()


def test_a_recipe_without_the_demonstrations_its_model_needs_stops_the_sweep(tmp_path) -> None:
    """The check qdil fit makes when a run starts, made for every trial before any starts."""
    root = tmp_path / "runs"
    command = ["sweep", str(SMOKE), str(IL), "--seeds", "0", "--root", str(root)]
    with pytest.raises(SystemExit, match=r"walker_il\.yaml: demos\.path: the gail reward model"):
        main([*command, "--demos.path", "null"])
    assert not root.exists()


def test_an_unreachable_cluster_address_is_named_within_seconds(tmp_path) -> None:
    root = tmp_path / "runs"
    started = time.monotonic()
    with pytest.raises(SystemExit, match=r"cannot reach the Ray cluster at '127\.0\.0\.1:1'"):
        main(["sweep", str(SMOKE), "--seeds", "0", "--address", "127.0.0.1:1", "--root", str(root)])
    assert time.monotonic() - started < 60  # ray.init alone waited for minutes


def test_a_spec_that_is_not_valid_yaml_is_named_with_its_line(tmp_path) -> None:
    spec = tmp_path / "broken.yaml"
    spec.write_text("name: broken\nstages:\n  - recipes: [a.yaml\n    seeds: [0]\n")
    with pytest.raises(SystemExit, match=r"broken\.yaml is not valid YAML at line \d+, column"):
        main(["sweep", str(spec)])


def test_a_killed_sweep_run_again_ends_as_its_plain_fits(one_ray, plain, tmp_path) -> None:
    """The driver, Ray and the trials killed at once (SIGKILL to the process group); the same
    command again finishes every trial as ``qdil fit`` would have, re-scores them and reports;
    once more, it finds every trial finished and writes nothing. (The killed sweep is a
    process of its own; the commands after it run in this process, on the suite's Ray.)"""
    root, report = tmp_path / "runs", tmp_path / "report"
    command = ["sweep", str(SMOKE), "--seeds", *SEEDS]
    command += ["--root", str(root), "--episodes", "1", "--report", str(report)]
    # a checkpoint every iteration: the kill lands with two of three iterations to go (with
    # the recipe's every 2, both trials could end their last one before the kill)
    command += ["--logging.checkpoint_every", "1"]
    sweep = start_qdil(*command, cwd=tmp_path)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and not list(root.glob("*/checkpoints/last.pt")):
        time.sleep(0.1)
    os.killpg(sweep.pid, signal.SIGKILL)
    sweep.wait()
    assert list(root.glob("*/checkpoints/last.pt")), "no trial reached a checkpoint"
    logged = [
        len(metrics(r)) for r in root.glob("walker_true-seed*") if (r / "metrics.csv").is_file()
    ]
    assert min(logged, default=0) < 3 or len(logged) < len(SEEDS)  # killed before the end
    assert not report.exists()
    qdil_here(command, tmp_path, WANDB_MODE="disabled")  # as user_env gives a process
    for seed in SEEDS:
        run = root / f"walker_true-seed{seed}"
        assert same_runs(run, plain / f"walker_true-seed{seed}")
        assert (run / "eval.json").is_file()  # re-scored
        assert "wandb_group: sweep-" in (run / "config.yaml").read_text()  # W&B groups them
    assert (report / "report.md").is_file()
    # the trial's re-scoring ran in its fit's process: the same scores as a `qdil eval`
    alone = tmp_path / "alone"
    shutil.copytree(plain / "walker_true-seed0", alone)
    main(["eval", str(alone), "--episodes", "1", "--num-threads", "1"])
    assert scores(root / "walker_true-seed0") == scores(alone)
    before = {p: p.stat().st_mtime_ns for p in root.glob("walker_*/**/*")}
    qdil_here(command, tmp_path, WANDB_MODE="disabled")  # as user_env gives a process
    assert before == {p: p.stat().st_mtime_ns for p in root.glob("walker_*/**/*")}
    for seed in SEEDS:  # and started no trial process: each log says why
        log = (root / ".locks" / f"walker_true-seed{seed}.log").read_text().splitlines()
        assert log[-1].endswith("finished and re-scored already; nothing to run"), log[-3:]


def test_a_trial_is_done_when_its_resume_would_find_it_finished_and_rescored(
    plain, tmp_path
) -> None:
    from qdil.sweeps.trainable import finished_and_rescored
    from qdil.sweeps.trials import Trial

    run = Path(shutil.copytree(plain / "walker_true-seed0", tmp_path / "walker_true-seed0"))
    trial = Trial(SMOKE, 0, (), run.name, tmp_path)
    assert finished_and_rescored(trial, 0)  # 3 of 3 iterations, nothing to re-score
    assert not finished_and_rescored(trial, 1)  # no eval.json yet
    longer = Trial(SMOKE, 0, (("qd.iterations", "5"),), run.name, tmp_path)
    assert not finished_and_rescored(longer, 0)  # the override continues it
    budget = Trial(SMOKE, 0, (("qd.iterations", "5"), ("qd.env_steps", "1")), run.name, tmp_path)
    assert finished_and_rescored(budget, 0)  # longer, but its step budget is spent
    main(["eval", str(run), "--episodes", "1", "--num-threads", "1"])
    assert finished_and_rescored(trial, 1) and not finished_and_rescored(trial, 2)
    (run / "checkpoints" / "last.pt").write_bytes(b"torn")
    assert not finished_and_rescored(trial, 0)  # the child reads it and says what is wrong


def test_sweep_help_lists_its_options() -> None:
    done = qdil("sweep", "--help", cwd=ROOT, check=True)
    for option in ("--seeds", "--cpus-per-trial", "--gpus-per-trial", "--address", "--report"):
        assert option in done.stdout


def test_a_sweep_on_a_two_node_cluster_equals_the_plain_fits(plain, tmp_path) -> None:
    """A head and a worker node of one CPU each on this machine, reached by ``--address``."""
    from ray.cluster_utils import Cluster

    if ray.is_initialized():  # the other tests' local Ray
        ray.shutdown()
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    cluster.add_node(num_cpus=1)
    try:
        root = tmp_path / "runs"
        command = ["sweep", str(SMOKE), "--seeds", "0", "1", "--root", str(root)]
        main([*command, "--episodes", "0", "--address", cluster.address])
        assert not ray.is_initialized()  # the sweep disconnected; the cluster runs on
        for seed in ("0", "1"):
            run = root / f"walker_true-seed{seed}"
            assert same_runs(run, plain / f"walker_true-seed{seed}")
    finally:
        cluster.shutdown()


def test_half_a_gpu_per_trial_packs_two_trials_onto_one_gpu(plain, tmp_path) -> None:
    """Ray told of one GPU (none is needed: the smoke recipe runs on the CPU): two trials of
    half a GPU each run at the same time, both given GPU 0, and equal the plain fits."""
    if ray.is_initialized():  # the other tests' Ray has no GPU
        ray.shutdown()
    ray.init(num_cpus=2, num_gpus=1, include_dashboard=False, log_to_driver=False)
    try:
        root = tmp_path / "runs"
        command = ["sweep", str(SMOKE), "--seeds", "0", "1", "--root", str(root)]
        main([*command, "--gpus-per-trial", "0.5", "--episodes", "0"])
    finally:
        ray.shutdown()
    spans = []
    for seed in ("0", "1"):
        assert same_runs(root / f"walker_true-seed{seed}", plain / f"walker_true-seed{seed}")
        log = (root / ".locks" / f"walker_true-seed{seed}.log").read_text()
        assert "CUDA_VISIBLE_DEVICES=0, GPU share 0.5" in log, log
        # the trial's `qdil fit` (its first command): when it started and ended
        stamps = [
            float(unix)
            for unix in re.findall(r"^# (?:started|ended) .*\(unix ([\d.]+)\)", log, re.M)
        ]
        spans.append((stamps[0], stamps[1]))
    assert max(start for start, _ in spans) < min(end for _, end in spans)  # at once
