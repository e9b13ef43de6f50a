"""The GPU check's tables (``gpu_check.md``, as docs/guides/gpu.md gives them)."""

from __future__ import annotations

from typing import Any

from benchmarks.gpu.probes import repeatability_table
from benchmarks.gpu.runs import PHASES
from qdil.envs.integrators import INTEGRATORS


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
    cheapest = result.get("iterations_cheapest") or {}
    for key, title in (
        ("iterations", "side by side, narrowed to the running episodes"),
        ("iterations_halfcheetah", "of HalfCheetah-v5 (as the first)"),
        ("iterations_humanoid", "of Humanoid-v5-newton (as the first)"),
        ("iterations_cheapest", f"as the first, with the {cheapest.get('integrator')} integrator"),
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
        rows = result[key]["rows"] if key == "iterations_cheapest" else result[key]
        for row in rows:
            cells = [str(row["iteration"]), f"{row['iter_seconds']:.1f}"]
            cells += [f"{row.get(f'{p}_seconds', float('nan')):.1f}" for p in PHASES]
            cells.append(f"{row.get('sps', float('nan')):,.0f}")
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    if "integrators" in result:
        lines += integrator_table(result["integrators"])
    if "packed" in result:
        lines += packed_table(result["packed"], result.get("iterations", []))
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


def integrator_table(costs: dict[str, dict[str, Any]]) -> list[str]:
    """ms per env step by task and integrator, and the ratio to the task's own."""
    names = [name for name in INTEGRATORS if any(name in row for row in costs.values())]
    lines = [
        "| ms per env step | own | " + " | ".join(names) + " |",
        "|---|---|" + "---|" * len(names),
    ]
    for task, row in costs.items():
        base = row.get(row["own"])
        cells = [
            f"{row[n]:.2f} ({row[n] / base:.2f}×)" if n in row and base else "–" for n in names
        ]
        lines.append(f"| {task} | {row['own']} | " + " | ".join(cells) + " |")
    return [*lines, ""]


def packed_table(packed: dict[str, Any], alone: list[dict[str, float]]) -> list[str]:
    """Each packed trial's seconds per iteration beside one run alone's."""
    seconds = {row["iteration"]: row["iter_seconds"] for row in alone}
    trials = packed["iterations"]
    lines = [
        f"Two trials of one `qdil sweep` at half a GPU each ({packed['seconds']:.0f} s in all):",
        "",
        "| iteration | one run alone, s | "
        + " | ".join(f"trial {i}, s" for i in range(len(trials)))
        + " |",
        "|" + "---|" * (len(trials) + 2),
    ]
    for iteration in sorted({row["iteration"] for rows in trials for row in rows}):
        cells = [str(iteration), f"{seconds.get(iteration, float('nan')):.1f}"]
        for rows in trials:
            mine = {row["iteration"]: row["iter_seconds"] for row in rows}
            cells.append(f"{mine[iteration]:.1f}" if iteration in mine else "–")
        lines.append("| " + " | ".join(cells) + " |")
    return [*lines, ""]
