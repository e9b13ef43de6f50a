"""benchmarks/gpu_check.py, scaled down on Warp's CPU device: every step runs and reports."""

from __future__ import annotations

import importlib
import json
from pathlib import Path

import pytest

pytest.importorskip("mujoco_warp", reason="the warp extra is not installed")

ROOT = Path(__file__).resolve().parents[1]


def _gpu_check():
    return importlib.import_module("benchmarks.gpu_check")


def test_the_check_runs_every_step_on_the_cpu(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    # the iterations in turns are a second fit (the batch's equality is tested elsewhere)
    args = ["--device", "cpu", "--quick", "--out", str(tmp_path / "out")]
    result = _gpu_check().main([*args, "--skip", "iterations_in_turns", "--budget", "3600"])
    assert result["errors"] == {}
    saved = json.loads((tmp_path / "out" / "gpu_check.json").read_text())
    assert saved["machine"]["card"] == "Warp CPU device"
    assert set(saved["throughput"]) == {"6", "24"}
    assert set(saved["floor"]) == {"1", "6"} and all(ms > 0 for ms in saved["floor"].values())
    breakdown = saved["breakdown"]
    # the autoreset's observed stages launch fewer kernels than the whole forward
    assert 0 < breakdown["warp_launches"]["observed"] < breakdown["warp_launches"]["forward"]
    assert breakdown["torch_ops"]["collect_step"] > 0 and breakdown["ms"]["face_step"] > 0
    assert all(sps > 0 for sps in saved["throughput"].values())
    # torch counts host syncs on CUDA alone; the rollout still runs and is timed
    assert saved["syncs"]["syncs"] is None and saved["syncs"]["num_envs"] == 6
    # narrowed; not (its baseline); graphed (on CUDA: Warp's CPU device steps eagerly)
    for key in ("iterations", "iterations_wide", "iterations_graphed", "iterations_deterministic"):
        assert [row["iteration"] for row in saved[key]] == [1, 2]
        for row in saved[key]:
            assert {"jacobian_seconds", "walk_seconds", "evaluate_seconds"} <= set(row)
    # a paper-scale iteration of each task, and Walker2d's with the cheapest integrator
    for key in ("iterations_halfcheetah", "iterations_humanoid"):
        assert [row["iteration"] for row in saved[key]] == [1, 2]
    costs = saved["integrators"]
    assert set(costs) == {"Walker2d-v5", "HalfCheetah-v5", "Humanoid-v5"}
    assert {row["own"] for row in costs.values()} == {"rk4", "euler"}
    assert all(row["euler"] > 0 and row["rk4"] > 0 for row in costs.values())
    cheapest = saved["iterations_cheapest"]
    walker = {k: v for k, v in costs["Walker2d-v5"].items() if isinstance(v, float)}
    assert cheapest["integrator"] == min(walker, key=walker.get)
    assert [row["iteration"] for row in cheapest["rows"]] == [1, 2]
    # two seeds of one sweep (on the CPU without a GPU to share), both through two iterations
    packed = saved["packed"]
    assert [[row["iteration"] for row in rows] for rows in packed["iterations"]] == [[1, 2]] * 2
    # two seeds at once, each its own `qdil fit` process, both through two iterations
    side = saved["side_by_side"]
    assert side["runs"] == 2 and not side["timed_out"]
    assert side["gpu_memory_mib_max"] is None  # no nvidia-smi here
    assert [[row["iteration"] for row in rows] for rows in side["iterations"]] == [[1, 2]] * 2
    assert all(row["iter_seconds"] > 0 for rows in side["iterations"] for row in rows)
    # Warp's CPU device plays the same computation to the same bits, narrowed or not
    pairs = saved["repeatability"]
    assert len(pairs) == 7 and all(pairs.values())
    assert {f: d for diffs in pairs.values() for f, d in diffs.items() if d != 0} == {}
    assert "| evaluation_narrowed_vs_wide |" in (tmp_path / "out" / "gpu_check.md").read_text()
    # the GPU tests skip without CUDA, and the check says so rather than failing
    outcomes = saved["tests"]["outcomes"]
    assert outcomes and set(outcomes.values()) == {"skipped"}
    table = (tmp_path / "out" / "gpu_check.md").read_text()
    assert "| 6 |" in table and "| 2 |" in table and "skipped" in table
    assert "2 runs at once" in table
    assert "| ms per env step | own |" in table and "half a GPU each" in table
    assert saved["kept"] == []
    # called again on the same card with the same folder: every step measured is kept
    again = _gpu_check().main([*args, "--budget", "3600"])
    assert again["kept"] == [key for key in again["kept"] if key in saved] and again["errors"] == {}
    assert "iterations_humanoid" in again["kept"] and "packed" in again["kept"]
    assert again["iterations"] == saved["iterations"] and "iterations_in_turns" not in again


def test_a_failed_step_is_reported_and_the_others_still_run(tmp_path: Path) -> None:
    result = _gpu_check().main(
        [
            *("--device", "cpu", "--quick", "--out", str(tmp_path)),
            "--skip=repeatability,breakdown,floor,throughput,iterations_in_turns,iterations_wide,"
            "iterations_graphed,iterations_deterministic,side_by_side,tests,integrators,"
            "iterations_halfcheetah,iterations_humanoid,iterations_cheapest,packed",
            "--set=--env.num_envs 5",  # not divisible by Walker2d's k + 1 = 3
        ]
    )
    assert "num_envs" in result["errors"]["syncs"] and "num_envs" in result["errors"]["iterations"]
    assert "Traceback" in result["tracebacks"]["iterations"]
    assert result["machine"]["card"] == "Warp CPU device"
    assert "- iterations failed:" in (tmp_path / "gpu_check.md").read_text()


def test_runs_side_by_side_cut_by_the_budget_keep_what_they_recorded(tmp_path: Path) -> None:
    check = _gpu_check()
    side = check.runs_side_by_side("cpu", check.QUICK, runs=2, iterations=2, timeout=1.0)
    assert side["timed_out"] and side["seconds"] < 30
    assert side["iterations"] == [[], []]  # no iteration finishes in a second; no error either
    table = check.markdown({"command": "gpu_check", "side_by_side": side})
    assert "Stopped by the check's budget" in table


def test_steps_left_when_the_budget_is_spent_are_listed(tmp_path: Path) -> None:
    check = _gpu_check()
    result = check.main(["--device", "cpu", "--quick", "--out", str(tmp_path), "--budget", "0"])
    assert result["errors"] == {} and result["seconds"] == {}  # nothing began
    assert result["machine"]["card"] == "Warp CPU device"  # the card is always named
    # in the order of their value: what no GPU has measured first
    assert result["not_run"][:3] == ["iterations_halfcheetah", "iterations_humanoid", "integrators"]
    assert "iterations_graphed" in result["not_run"]
    assert (
        "- not run, the budget spent: iterations_halfcheetah, iterations_humanoid,"
        in (tmp_path / "gpu_check.md").read_text()
    )


def test_a_record_of_other_code_or_another_card_is_not_kept(tmp_path: Path) -> None:
    check = _gpu_check()
    here = {"card": "NVIDIA H200", "code": "abc"}
    record = {"machine": here, "iterations": [{"iteration": 1}], "errors": {"floor": "x"}}
    (tmp_path / "gpu_check.json").write_text(json.dumps(record))
    assert check.earlier(tmp_path, here, fresh=False)["iterations"] == [{"iteration": 1}]
    assert "floor" not in check.earlier(tmp_path, here, fresh=False)  # failed: run again
    assert check.earlier(tmp_path, here | {"code": "def"}, fresh=False) == {}
    assert check.earlier(tmp_path, here | {"card": "NVIDIA H100"}, fresh=False) == {}
    assert check.earlier(tmp_path, here, fresh=True) == {}
