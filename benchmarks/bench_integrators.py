"""What another integrator costs and changes (``env.integrator``, issue 51).

Two measurements, each against the task model's own integrator in the same process:

- ``--steps``: the cost of one env step (frame skip and all) of each task with each
  integrator, random actions, autoreset on, timed after a warm-up; on MuJoCo's C engine
  (``--backend mujoco``, the CPU) or MuJoCo Warp (``--backend warp --device cuda``; the GPU
  check calls :func:`step_costs` the same way);
- ``--runs RUN_DIR ...``: how far trained elites' returns move when replayed under each
  integrator: the ``--top`` best elites of each run's true-keyed archive, ``--episodes``
  deterministic episodes each, the same reset seeds under every integrator.

    python benchmarks/bench_integrators.py --steps --runs runs/walker_ppga-seed0 --out out

writes ``integrators.json`` and prints markdown tables.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from qdil.envs.integrators import INTEGRATORS, own_integrator
from qdil.envs.tasks import make_task

TASKS = ("Walker2d-v5", "HalfCheetah-v5", "Humanoid-v5")
WARP_TASK = {"Humanoid-v5": "Humanoid-v5-newton"}  # MuJoCo Warp has no PGS solver


def step_costs(
    tasks: tuple[str, ...] = TASKS,
    *,
    backend: str = "mujoco",
    device: str = "cpu",
    num_envs: int = 64,
    steps: int = 20,
    rounds: int = 5,
    integrators: tuple[str, ...] = tuple(INTEGRATORS),
) -> dict[str, dict[str, Any]]:
    """Milliseconds per env step of ``num_envs`` simulations, by task and integrator.

    The integrators of a task take turns, ``rounds`` times ``steps`` steps each after a
    warm-up round, and each one's figure is its median round: a noisy machine slows them
    alike. The C engine steps on one thread.

    Returns:
        ``{task: {integrator: ms, ..., "own": name}}``; an integrator the backend refuses
        is left out, with its error under ``"errors"``.
    """
    import torch

    from qdil.envs.vector import LocomotionVectorEnv

    result: dict[str, Any] = {}
    for task in tasks:
        name = WARP_TASK.get(task, task) if backend == "warp" else task
        row: dict[str, Any] = {"own": own_integrator(make_task(name).xml_path)}
        envs = {}
        for integrator in integrators:
            try:
                envs[integrator] = LocomotionVectorEnv(
                    name, num_envs, backend=backend, device=device, num_threads=1,
                    integrator=integrator,
                )  # fmt: skip
            except (ValueError, NotImplementedError) as error:
                row.setdefault("errors", {})[integrator] = f"{type(error).__name__}: {error}"
        rng = np.random.default_rng(0)
        times: dict[str, list[float]] = {integrator: [] for integrator in envs}
        for round_ in range(rounds + 1):  # round 0 warms up: kernels compiled, caches warm
            for integrator, env in envs.items():
                if round_ == 0:
                    env.reset(seed=0)
                low, high = env.single_action_space.low, env.single_action_space.high
                actions = rng.uniform(low, high, (steps, num_envs, low.size))
                if env.device.type == "cuda":
                    torch.cuda.synchronize(env.device)
                start = time.perf_counter()
                for action in actions:
                    env.step(action)
                if env.device.type == "cuda":
                    torch.cuda.synchronize(env.device)
                if round_:
                    times[integrator].append(1e3 * (time.perf_counter() - start) / steps)
        for integrator, env in envs.items():
            row[integrator] = float(np.median(times[integrator]))
            env.close()
        result[task] = row
    return result


def elite_returns(
    run_dir: Path,
    *,
    top: int = 5,
    episodes: int = 3,
    integrators: tuple[str, ...] = tuple(INTEGRATORS),
) -> dict[str, Any]:
    """Mean returns of a run's best elites replayed under each integrator.

    Returns:
        ``{"task", "own", "elites": [{"cell", "returns": {integrator: mean}}, ...]}``, the
        elites the ``top`` best of the true-keyed archive by their training return.
    """
    from qdil.evaluation.rescore import ReplaySettings
    from qdil.export.policies import scoring_episodes
    from qdil.qd.checkpoint import load_archive

    settings = ReplaySettings.of_run(run_dir)
    archive, iteration = load_archive(run_dir, "true")
    elites = archive.data()
    rows = np.argsort(-elites["objective"])[:top]
    own = settings.integrator or own_integrator(make_task(settings.task).xml_path)
    out: dict[str, Any] = {"run": str(run_dir), "task": settings.task, "iteration": iteration}
    out["own"], out["elites"] = own, []
    for row in rows:
        fields = {key: elites[key][row] for key in ("obs_mean", "obs_var", "obs_count")}
        returns = {}
        for integrator in integrators:
            replay = dataclasses.replace(settings, integrator=integrator)
            played = scoring_episodes(replay, elites["solution"][row], fields, episodes, seed=0)
            returns[integrator] = float(np.mean([episode["return"] for episode in played]))
        cell = archive.int_to_grid_index(elites["index"][row : row + 1])[0].tolist()
        out["elites"].append(
            {"cell": cell, "training_return": float(elites["objective"][row])}
            | {"returns": returns}
        )
    return out


def markdown(result: dict[str, Any]) -> str:
    """The tables: step cost against the own integrator, and elites' returns under each."""
    lines = []
    for backend, costs in result.get("steps", {}).items():
        lines += [f"Step cost, {backend} (ms per env step; × the task's own integrator)", ""]
        lines += [
            "| task | own | " + " | ".join(INTEGRATORS) + " |",
            "|---|---|" + "---|" * len(INTEGRATORS),
        ]
        for task, row in costs.items():
            base = row.get(row["own"])
            cells = [
                f"{row[name]:.2f} ({row[name] / base:.2f}×)" if name in row and base else "–"
                for name in INTEGRATORS
            ]
            lines.append(f"| {task} | {row['own']} | " + " | ".join(cells) + " |")
        lines.append("")
    for run in result.get("runs", []):
        lines += [f"Elites of `{run['run']}` ({run['task']}, own {run['own']}): mean return", ""]
        lines += ["| cell | " + " | ".join(INTEGRATORS) + " |", "|---|" + "---|" * len(INTEGRATORS)]
        for elite in run["elites"]:
            own = elite["returns"][run["own"]]
            cells = [f"{value:,.0f} ({value - own:+,.0f})" for value in elite["returns"].values()]
            lines.append(f"| {elite['cell']} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", action="store_true", help="time a step per integrator")
    parser.add_argument("--backend", default="mujoco", help="mujoco (default) or warp")
    parser.add_argument("--device", default="cpu", help="cpu (default) or cuda")
    parser.add_argument("--num-envs", type=int, default=64, help="simulations stepped at once")
    parser.add_argument("--runs", nargs="*", type=Path, default=[], help="run directories")
    parser.add_argument("--top", type=int, default=5, help="best elites per run")
    parser.add_argument("--episodes", type=int, default=3, help="episodes per elite")
    parser.add_argument("--out", type=Path, default=Path("integrators"), help="output folder")
    args = parser.parse_args(argv)
    result: dict[str, Any] = {"command": " ".join(["python", *sys.argv])}
    if args.steps:
        costs = step_costs(backend=args.backend, device=args.device, num_envs=args.num_envs)
        result["steps"] = {f"{args.backend} {args.device}, N = {args.num_envs}": costs}
    result["runs"] = [elite_returns(run, top=args.top, episodes=args.episodes) for run in args.runs]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "integrators.json").write_text(json.dumps(result, indent=1))
    print(markdown(result))
    return result


if __name__ == "__main__":
    main()
