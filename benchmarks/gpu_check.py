"""The GPU check: tests, rollout throughput, host syncs and a paper-scale QD iteration.

One command on a machine with a CUDA GPU and the warp extra (at most about 8 minutes on one
H100 or H200)::

    python benchmarks/gpu_check.py --out gpu_check

measures, in steady state (kernels compiled and Warp graphs recorded before any clock runs):

0. the GPU tests (``pytest -m gpu -n 0 tests/test_gpu.py tests/envs/test_warp_backend.py``),
   first, so that a check cut short by its budget still says what is correct; then how far
   a training rollout and an evaluation land from themselves when played again (eagerly,
   from a CUDA graph, narrowed or not): MuJoCo Warp on CUDA is not repeatable bit for bit;
1. where one training env step's time goes at the paper's N = 3,000: each recorded Warp
   sequence (substeps, sensor pass, reset, the reset's observed stages of ``forward``, and
   the whole ``forward`` for comparison), the torch face's step (also replayed from one
   CUDA graph) and a collector step, with the Warp launches and torch operators behind
   them and the solver's iterations; and one frame skip replayed at N = 1, 256, 3,000 and
   16,384 (its latency floor);
2. rollout-face env-steps/s (:class:`qdil.envs.torch_vector.TorchVectorEnv`, no host copy,
   autoreset on) at N = 1,024, 4,096 and 16,384 simulations of Walker2d-v5;
3. host syncs per env step in a training rollout of the paper's size (the GPU recipe's
   3,000 simulations, 128 steps), counted by torch's sync debug mode;
4. two QD iterations of ``recipes/gpu/walker_mcwae.yaml`` through ``qdil fit``, with each
   phase's seconds from ``metrics.csv`` (the second iteration is the figure: the first
   records graphs and builds the reward model's optimiser state); the same without
   narrowing (``WarpBatch.narrow``), with each training step replayed from one CUDA graph
   (``TorchVectorEnv.step_graph``) and on MuJoCo Warp's deterministic kernels
   (``env.deterministic``); when asked for (``--skip ''``), also with θ_μ
   and its branches scored one after the other (``--env.eval_envs 3000``), the baseline of
   scoring them side by side;
5. when asked for, the same two QD iterations as ``--runs`` separate ``qdil fit`` processes
   at once (seeds 0, 1, ...) sharing the card, each run's seconds per iteration against
   the one run of step 4: what several seeds side by side cost.

The probes below a QD iteration (steps 1 to 3) live in ``benchmarks/gpu_probes.py``.

It writes ``gpu_check.json`` (after every step, so a check cut short keeps what it
measured) and ``gpu_check.md``, the tables of docs/guides/gpu.md. ``--device cpu --quick``
runs the same code on Warp's CPU device, scaled down (the test suite runs it); its figures
are not a GPU's.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
import traceback
import xml.etree.ElementTree as ElementTree
from collections.abc import Callable
from pathlib import Path
from typing import Any
from unittest import mock

sys.path.insert(0, str(Path(__file__).resolve().parent))  # gpu_probes, beside this file
from gpu_probes import (
    RECIPE,
    frame_skip_floor,
    machine,
    repeatability,
    repeatability_table,
    rollout_syncs,
    rollout_throughput,
    step_breakdown,
)

ROOT = Path(__file__).resolve().parents[1]
GPU_TESTS = ["tests/test_gpu.py", "tests/envs/test_warp_backend.py"]
PHASES = ("jacobian", "walk", "evaluate", "reward_update")
MEASURED = ("iterations_in_turns", "side_by_side")
"""Steps left out unless asked for: measured (docs/guides/gpu.md), and 4 minutes together."""
# the same recipe, scaled down for Warp's CPU device (--quick): every phase still runs
QUICK = [
    "--env.num_envs", "6", "--env.max_episode_steps", "40",
    "--rl.init_args.rollout_length", "8", "--rl.init_args.jacobian_iterations", "1",
    "--rl.init_args.walk_iterations", "1", "--rl.init_args.num_minibatches", "2",
    "--rl.init_args.update_epochs", "1", "--qd.emitter.init_args.batch_size", "3",
    "--qd.branch_episodes", "1", "--qd.mean_episodes", "3", "--reward.init_args.batch_size", "1000",
]  # fmt: skip


def qd_iterations(
    device: str,
    overrides: list[str],
    iterations: int,
    narrow: bool = True,
    graphed: bool = False,
) -> list[dict[str, float]]:
    """Each iteration's seconds, per phase, of ``qdil fit`` on the GPU recipe.

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
            argv = ["fit", str(RECIPE), "--env.device", device, *overrides]
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
    for key, title in (
        ("iterations", "side by side, narrowed to the running episodes"),
        ("iterations_in_turns", "in turns"),
        ("iterations_wide", "side by side, every simulation to the end (not narrowed)"),
        ("iterations_graphed", "as the first, each training step replayed from a CUDA graph"),
        ("iterations_deterministic", "as the first, on MuJoCo Warp's deterministic kernels"),
    ):
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
    if "side_by_side" in result:
        side = result["side_by_side"]
        alone = {row["iteration"]: row["iter_seconds"] for row in result.get("iterations", [])}
        memory = side["gpu_memory_mib_max"]
        lines += [
            f"{side['runs']} runs at once (separate processes, seeds 0 to {side['runs'] - 1}"
            + (f", at most {memory:,.0f} MiB of GPU memory in use" if memory else "")
            + "):",
            "",
            "| iteration | one run alone, s | "
            + " | ".join(f"seed {s}, s" for s in range(side["runs"]))
            + " |",
            "|" + "---|" * (side["runs"] + 2),
        ]
        done = {row["iteration"]: row for rows in side["iterations"] for row in rows}
        for iteration in sorted(done):
            cells = [str(iteration), f"{alone.get(iteration, float('nan')):.1f}"]
            for rows in side["iterations"]:
                seconds = {row["iteration"]: row["iter_seconds"] for row in rows}
                cells.append(f"{seconds[iteration]:.1f}" if iteration in seconds else "not reached")
            lines.append("| " + " | ".join(cells) + " |")
        if side["timed_out"]:
            lines.append(f"\nStopped by the check's budget after {side['seconds']:.0f} s.")
        lines.append("")
    if "repeatability" in result:
        lines += repeatability_table(result["repeatability"])
    if "tests" in result:
        lines += ["| GPU test | result |", "|---|---|"]
        lines += [f"| `{name}` | {o} |" for name, o in result["tests"]["outcomes"].items()]
        lines.append("")
    for step, error in result.get("errors", {}).items():
        lines.append(f"- {step} failed: {error}")
    if result.get("not_run"):
        lines.append(f"- not run, the budget spent: {', '.join(result['not_run'])}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--device", default="cuda", help="cuda (default) or cpu")
    parser.add_argument("--quick", action="store_true", help="scaled down (Warp's CPU device)")
    parser.add_argument("--out", type=Path, default=Path("gpu_check"), help="output folder")
    parser.add_argument("--budget", type=float, default=480.0, help="seconds for all steps")
    parser.add_argument(
        "--skip",
        default=",".join(MEASURED),
        help="comma-separated steps to leave out (default: "
        f"{','.join(MEASURED)}, measured on an H100 on 2026-11-27; --skip '' runs all)",
    )
    parser.add_argument("--runs", type=int, default=2, help="runs at once for side_by_side")
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
        # first: what is correct matters more than what is fast when the budget runs out
        "tests": lambda: gpu_tests(min(240.0, args.budget - (time.perf_counter() - start))),
        "repeatability": lambda: repeatability(args.device, args.quick),
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
        # the same iterations with each training step replayed from one CUDA graph
        "iterations_graphed": lambda: qd_iterations(args.device, overrides, 2, graphed=True),
        # the same iterations on MuJoCo Warp's deterministic kernels: what repeatability costs
        "iterations_deterministic": lambda: qd_iterations(
            args.device, [*overrides, "--env.deterministic", "true"], 2
        ),
        # the same iterations with the ended evaluation episodes kept in the batch
        "iterations_wide": lambda: qd_iterations(args.device, overrides, 2, narrow=False),
        "side_by_side": lambda: runs_side_by_side(
            args.device, overrides, args.runs, 2, args.budget - 45 - (time.perf_counter() - start)
        ),
    }

    def save() -> None:  # after every step: a check cut short keeps what it measured
        (args.out / "gpu_check.json").write_text(json.dumps(result, indent=1))
        (args.out / "gpu_check.md").write_text(markdown(result))

    for name, step in steps.items():
        if name in args.skip.split(","):
            continue
        if time.perf_counter() - start > args.budget:  # a step begun may run over, no more
            result.setdefault("not_run", []).append(name)
            continue
        began = time.perf_counter()
        try:
            result[name] = step()
        except (Exception, SystemExit) as error:  # a finding; the other steps still run
            result["errors"][name] = f"{type(error).__name__}: {error}"
            result.setdefault("tracebacks", {})[name] = traceback.format_exc()
        result.setdefault("seconds", {})[name] = time.perf_counter() - began
        save()
        print(f"{name}: {result['seconds'][name]:.1f} s", flush=True)
    save()
    print(markdown(result))
    return result


if __name__ == "__main__":
    main()
