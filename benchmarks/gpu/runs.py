"""The GPU check's steps that run ``qdil``: QD iterations, runs side by side or packed by a
sweep, and the GPU tests (see ``benchmarks/gpu_check.py``)."""

from __future__ import annotations

import contextlib
import csv
import os
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ElementTree
from pathlib import Path
from typing import Any
from unittest import mock

from benchmarks.gpu.probes import RECIPE

ROOT = Path(__file__).resolve().parents[2]
GPU_TESTS = ["tests/test_gpu.py", "tests/envs/test_warp_backend.py"]
PHASES = ("jacobian", "walk", "evaluate", "reward_update")
RECIPES = {
    "Walker2d-v5": RECIPE,
    "HalfCheetah-v5": ROOT / "recipes" / "gpu" / "halfcheetah_mcwae.yaml",
    "Humanoid-v5": ROOT / "recipes" / "gpu" / "humanoid_mcwae.yaml",
}
"""The paper-scale GPU recipe of each task (Humanoid's runs the Newton-solver variant)."""


def qd_iterations(
    device: str,
    overrides: list[str],
    iterations: int,
    narrow: bool = True,
    graphed: bool = False,
    recipe: Path = RECIPE,
) -> list[dict[str, float]]:
    """Each iteration's seconds, per phase, of ``qdil fit`` on a GPU recipe (Walker2d's).

    ``narrow=False`` keeps every simulation of an evaluation in the batch to its end (the
    ended episodes' worlds stepped and restored): the baseline of narrowing. ``graphed``
    replays each training step from one CUDA graph (``TorchVectorEnv.step_graph``).
    """
    from qdil.cli import main
    from qdil.envs.torch_vector import TorchVectorEnv

    here = Path.cwd()
    with tempfile.TemporaryDirectory() as folder, contextlib.ExitStack() as stack:
        if not narrow:
            stack.enter_context(mock.patch.object(TorchVectorEnv, "narrow", return_value=None))
        if graphed:
            stack.enter_context(mock.patch.object(TorchVectorEnv, "step_graph", True))
        os.chdir(folder)
        try:
            argv = ["fit", str(recipe), "--env.device", device, *overrides]
            argv += ["--qd.iterations", str(iterations), "--name", "gpu_check"]
            argv += ["--logging.wandb", "disabled", "--logging.progress", "false"]
            main(argv)
            rows = _metrics(Path(folder) / "runs" / "gpu_check" / "metrics.csv")
        finally:
            os.chdir(here)
    return rows


def _metrics(path: Path) -> list[dict[str, float]]:
    """Each iteration's seconds per phase, env steps and env-steps/s from a ``metrics.csv``."""
    with open(path, newline="") as file:
        rows = list(csv.DictReader(file))
    keep = ["iter_seconds", "env_steps", "sps", *(f"{p}_seconds" for p in PHASES)]
    return [
        {key: float(row[f"perf/{key}"]) for key in keep if row.get(f"perf/{key}", "") != ""}
        | {"iteration": int(row["iteration"])}
        for row in rows
    ]


def _gpu_memory_mib() -> float | None:
    """Memory in use on the first GPU, as ``nvidia-smi`` reports it (None without one)."""
    if shutil.which("nvidia-smi") is None:
        return None
    query = ["nvidia-smi", "--query-gpu=memory.used", "--format=csv,noheader,nounits"]
    done = subprocess.run(query, capture_output=True, text=True, timeout=10)
    return float(done.stdout.split()[0]) if done.returncode == 0 and done.stdout else None


def runs_side_by_side(
    device: str, overrides: list[str], runs: int, iterations: int, timeout: float
) -> dict[str, Any]:
    """``runs`` separate ``qdil fit`` processes of the recipe at once, seeds 0, 1, ...

    Each is its own process with its own CUDA context, as a researcher would start seeds;
    the card's memory in use is polled while they run.
    """
    with tempfile.TemporaryDirectory() as folder:
        processes = []
        for seed in range(runs):
            argv = [sys.executable, "-m", "qdil.cli", "fit", str(RECIPE), "--env.device", device]
            argv += [*overrides, "--qd.iterations", str(iterations), "--seed", str(seed)]
            argv += ["--name", f"seed{seed}", "--logging.wandb", "disabled"]
            argv += ["--logging.progress", "false"]
            log = open(Path(folder) / f"seed{seed}.log", "w")  # noqa: SIM115 (closed below)
            processes.append((subprocess.Popen(argv, cwd=folder, stdout=log, stderr=log), log))
        start, memory, timed_out = time.perf_counter(), [], False
        while any(p.poll() is None for p, _ in processes):
            if time.perf_counter() - start > timeout:  # keep what the runs recorded so far
                timed_out = True
                for p, _ in processes:
                    p.kill()
                break
            memory.append(_gpu_memory_mib())
            time.sleep(1.0)
        seconds = time.perf_counter() - start
        for _, log in processes:
            log.close()
        failed = {
            seed: (Path(folder) / f"seed{seed}.log").read_text()[-2000:]
            for seed, (p, _) in enumerate(processes)
            if p.wait() != 0 and not timed_out
        }
        if failed:
            raise RuntimeError(f"runs side by side failed: {failed}")
        metrics = [Path(folder) / "runs" / f"seed{s}" / "metrics.csv" for s in range(runs)]
        rows = [_metrics(path) if path.exists() else [] for path in metrics]
    used = [m for m in memory if m is not None]
    return {
        "runs": runs,
        "seconds": seconds,
        "timed_out": timed_out,
        "iterations": rows,
        "gpu_memory_mib_max": max(used) if used else None,
    }


def packed_trials(device: str, overrides: list[str], iterations: int) -> dict[str, Any]:
    """Two seeds as one ``qdil sweep`` of half a GPU per trial: Ray packs both on the card.

    Returns:
        Each trial's iterations (seconds per phase, from its ``metrics.csv``) and the
        sweep's wall-clock seconds; the figure is each trial's seconds per iteration
        against one run alone (the ``iterations`` step).
    """
    with tempfile.TemporaryDirectory() as folder:
        argv = [sys.executable, "-m", "qdil.cli", "sweep", str(RECIPE), "--seeds", "0", "1"]
        gpus = "0.5" if device.startswith("cuda") else "0"  # on the CPU: two trials at once
        argv += ["--gpus-per-trial", gpus, "--episodes", "0", "--root", "runs"]
        argv += ["--env.device", "cuda" if device.startswith("cuda") else device, *overrides]
        argv += ["--qd.iterations", str(iterations), "--logging.wandb", "disabled"]
        start = time.perf_counter()
        done = subprocess.run(argv, cwd=folder, capture_output=True, text=True)
        seconds = time.perf_counter() - start
        if done.returncode != 0:
            raise RuntimeError(f"qdil sweep failed: {(done.stdout + done.stderr)[-3000:]}")
        paths = sorted(Path(folder, "runs").glob("*-seed*/metrics.csv"))
        return {"seconds": seconds, "iterations": [_metrics(path) for path in paths]}


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
        if not report.exists():  # pytest stopped before running a test (a usage or import error)
            raise RuntimeError(f"pytest ran no test: {(done.stdout + done.stderr)[-3000:]}")
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
