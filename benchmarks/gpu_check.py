"""The GPU check: tests, a paper-scale QD iteration of each task, integrators, probes.

One command on a machine with a CUDA GPU and the warp extra::

    python -m benchmarks.gpu_check --out gpu_check

runs its steps in the order of their value, in steady state (kernels compiled and Warp
graphs recorded before any clock runs), until its budget (480 s) is spent:

1. ``iterations_halfcheetah``, ``iterations_humanoid``: two QD iterations of each task's
   paper-scale recipe (``recipes/gpu/*_mcwae.yaml``) through ``qdil fit``, each phase's
   seconds from ``metrics.csv`` (the second iteration is the figure: the first records
   graphs and builds the reward model's optimiser state); no GPU has measured them yet;
2. ``integrators``: one env step of each task with each integrator (``env.integrator``) at
   the paper's N = 3,000, the per-step probe of ``benchmarks/bench_integrators.py``;
3. ``iterations_cheapest``: Walker2d's iterations with the integrator that step found
   cheapest (Euler if it did not run), then ``iterations``: Walker2d's with its own (RK4);
4. ``iterations_deterministic``: the same on MuJoCo Warp's deterministic kernels
   (``env.deterministic``): what repeatability costs;
5. ``packed``: two seeds as one ``qdil sweep`` at half a GPU per trial, against one alone;
6. ``tests``: the GPU tests (``pytest -m gpu -n 0 tests/test_gpu.py
   tests/envs/test_warp_backend.py``);
7. ``repeatability``: how far a training rollout and an evaluation land from themselves when
   played again (eagerly, from a CUDA graph, narrowed or not);
8. the probes of ``benchmarks/gpu/probes.py``, measured on an H200 on 2026-11-27: ``breakdown``
   (one training step's Warp sequences and torch operators at N = 3,000), ``floor`` (one frame
   skip at N = 1 to 16,384), ``throughput`` (rollout env-steps/s), ``syncs`` (host syncs per
   step), and the iterations without narrowing (``iterations_wide``) and graphed
   (``iterations_graphed``);
9. when asked for (``--skip ''``): ``iterations_in_turns`` (θ_μ and its branches scored one
   after the other) and ``side_by_side`` (``--runs`` separate ``qdil fit`` processes at once).

It writes ``gpu_check.json`` after every step and ``gpu_check.md`` (the tables of
docs/guides/gpu.md). Run again with the same ``--out``, it keeps every step that folder's
``gpu_check.json`` measured without error on the same card with the same code (a hash of
``src/qdil``, ``benchmarks`` and the GPU recipes: the machine's copy has no git) and runs
the rest (``--fresh`` runs all again): a GPU lent for minutes at a time finishes the check
over several calls.
``--device cpu --quick`` runs the same code scaled down on Warp's CPU device (the test suite
runs it); its figures are not a GPU's.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

if not __package__:  # run as a file, the package beside it is out of reach
    sys.exit("run the GPU check from the repository's root: python -m benchmarks.gpu_check ...")

from benchmarks.bench_integrators import TASKS, step_costs
from benchmarks.gpu.probes import (
    frame_skip_floor,
    machine,
    repeatability,
    rollout_syncs,
    rollout_throughput,
    step_breakdown,
)
from benchmarks.gpu.runs import (
    RECIPES,
    gpu_tests,
    packed_trials,
    qd_iterations,
    runs_side_by_side,
)
from benchmarks.gpu.tables import markdown

MEASURED = ("iterations_in_turns", "side_by_side")
"""Steps left out unless asked for: measured (docs/guides/gpu.md), and 4 minutes together."""
# the same recipes, scaled down for Warp's CPU device (--quick): every phase still runs
QUICK = [
    "--env.num_envs", "6", "--env.max_episode_steps", "40",
    "--rl.init_args.rollout_length", "8", "--rl.init_args.jacobian_iterations", "1",
    "--rl.init_args.walk_iterations", "1", "--rl.init_args.num_minibatches", "2",
    "--rl.init_args.update_epochs", "1", "--qd.emitter.init_args.batch_size", "3",
    "--qd.branch_episodes", "1", "--qd.mean_episodes", "3", "--reward.init_args.batch_size", "1000",
]  # fmt: skip


def cheapest(result: dict[str, Any], task: str = "Walker2d-v5") -> str:
    """The integrator of the cheapest step ``result["integrators"]`` measured for ``task``."""
    row = (result.get("integrators") or {}).get(task) or {}
    timed = {name: ms for name, ms in row.items() if isinstance(ms, float)}
    return min(timed, key=timed.__getitem__) if timed else "euler"


def earlier(out: Path, machine: dict[str, Any], fresh: bool) -> dict[str, Any]:
    """The steps a previous check in ``out`` measured without error on the same card with
    the same code (``machine``'s ``card`` and ``code``); nothing where either differs."""
    path = out / "gpu_check.json"
    if fresh or not path.is_file():
        return {}
    try:
        before = json.loads(path.read_text())
    except ValueError:  # a file cut mid-write by a killed check: start over
        return {}
    held = before.get("machine") or {}
    if (held.get("card"), held.get("code")) != (machine["card"], machine["code"]):
        return {}
    dropped = {*before.get("errors", {}), "errors", "tracebacks", "not_run", "kept"}
    return {key: value for key, value in before.items() if key not in dropped}


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
    parser.add_argument("--fresh", action="store_true", help="measure every step again")
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
    n = 6 if args.quick else 3000
    command = "python -m benchmarks.gpu_check " + " ".join(argv or sys.argv[1:])
    info = machine(args.device)
    result: dict[str, Any] = earlier(args.out, info, args.fresh)
    result |= {"command": command.strip(), "device": args.device, "machine": info, "errors": {}}

    def iterations(task: str, extra: tuple[str, ...] = ()) -> list[dict[str, float]]:
        return qd_iterations(args.device, [*overrides, *extra], 2, recipe=RECIPES[task])

    steps: dict[str, Callable[[], Any]] = {
        # first: the figures no GPU has measured yet (Walker2d's iteration has one)
        "iterations_halfcheetah": lambda: iterations("HalfCheetah-v5"),
        "iterations_humanoid": lambda: iterations("Humanoid-v5"),
        "integrators": lambda: step_costs(
            TASKS,
            backend="warp",
            device=args.device,
            num_envs=n,
            steps=3 if args.quick else 20,
            rounds=1 if args.quick else 5,
        ),
        "iterations_cheapest": lambda: {
            "integrator": cheapest(result),
            "rows": iterations("Walker2d-v5", ("--env.integrator", cheapest(result))),
        },
        "iterations": lambda: iterations("Walker2d-v5"),  # the cheapest one's baseline
        "iterations_deterministic": lambda: iterations(
            "Walker2d-v5", ("--env.deterministic", "true")
        ),
        "packed": lambda: packed_trials(args.device, overrides, 2),
        "tests": lambda: gpu_tests(min(240.0, args.budget - (time.perf_counter() - start))),
        "repeatability": lambda: repeatability(args.device, args.quick),
        "breakdown": lambda: step_breakdown(args.device, n, 3 if args.quick else 50),
        "floor": lambda: frame_skip_floor(
            args.device, [1, 6] if args.quick else [1, 256, 3000, 16384], 3 if args.quick else 100
        ),
        "throughput": lambda: rollout_throughput(args.device, sizes, 10 if args.quick else 100),
        "syncs": lambda: rollout_syncs(args.device, overrides, 8 if args.quick else None),
        # the same iterations with the ended evaluation episodes kept in the batch
        "iterations_wide": lambda: qd_iterations(args.device, overrides, 2, narrow=False),
        # the same iterations with each training step replayed from one CUDA graph
        "iterations_graphed": lambda: qd_iterations(args.device, overrides, 2, graphed=True),
        # the same iterations with θ_μ and its branches scored one after the other
        "iterations_in_turns": lambda: iterations("Walker2d-v5", ("--env.eval_envs", str(turns))),
        "side_by_side": lambda: runs_side_by_side(
            args.device, overrides, args.runs, 2, args.budget - 45 - (time.perf_counter() - start)
        ),
    }

    result["kept"] = [name for name in steps if name in result]  # an earlier call measured
    seconds = result.setdefault("seconds", {})
    result["seconds"] = {name: s for name, s in seconds.items() if name in result["kept"]}

    def save() -> None:  # after every step: a check cut short keeps what it measured
        (args.out / "gpu_check.json").write_text(json.dumps(result, indent=1))
        (args.out / "gpu_check.md").write_text(markdown(result))

    for name, step in steps.items():
        if name in args.skip.split(",") or name in result["kept"]:
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
