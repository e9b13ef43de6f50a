"""tools/device_stage.py and tools/device_receive.sh: what travels to the GPU machine, and
that parts carried one call at a time unpack into the same files."""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("device_stage", ROOT / "tools/device_stage.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_what_is_staged_is_what_the_machine_lacks() -> None:
    staged = _tool().needed()
    for name in ("warp-lang", "mujoco-warp", "mujoco", "ribs", "gymnasium", "ray", "sybil"):
        assert name in staged, name  # the physics, the archives, the tasks, packed trials
    assert "jsonargparse" in staged and "typeshed-client" in staged  # followed through
    for name in ("torch", "lightning", "numpy", "numba", "scipy", "wandb", "qdil"):
        assert name not in staged, name  # the machine's own, left out, or the tree's src/


@pytest.mark.skipif(shutil.which("git") is None, reason="git")
def test_a_folder_left_behind_is_not_counted_in_what_a_call_carries() -> None:
    tool = _tool()
    names = subprocess.run(
        ["git", "ls-files", "-z", "docs"], cwd=ROOT, check=True, capture_output=True, text=True
    ).stdout.split("\0")
    docs = sum((ROOT / n).lstat().st_size for n in names if n and os.path.lexists(ROOT / n))
    assert docs > 0
    assert tool.tree_size(("docs",)) == tool.tree_size() - docs
    assert tool.tree_size(("doc",)) == tool.tree_size()  # a folder, not a prefix of names


@pytest.mark.skipif(shutil.which("xz") is None or shutil.which("git") is None, reason="xz, git")
def test_parts_carried_one_call_at_a_time_unpack_into_the_same_site(tmp_path: Path) -> None:
    site = tmp_path / "site"
    (site / "pkg").mkdir(parents=True)
    (site / "pkg" / "__init__.py").write_text("VALUE = 1\n")
    (site / "pkg" / "data.bin").write_bytes(os.urandom(5000))  # incompressible: several parts
    out = tmp_path / "stage"
    out.mkdir()
    plan = _tool().pack(site, out, room=2000, plan={"packages": {}})
    assert plan["parts"] >= 3
    machine = {  # the machine's /tmp, kept between calls
        "QDIL_STAGE_STORE": str(tmp_path / "machine" / "store"),
        "QDIL_STAGE_SITE": str(tmp_path / "machine" / "site"),
    }
    for k in range(1, plan["parts"] + 1):
        call = tmp_path / f"call{k}"  # the tree a call carries: the script and one part
        (call / "tools").mkdir(parents=True)
        shutil.copy(ROOT / "tools" / "device_receive.sh", call / "tools")
        shutil.copytree(out / f"call-{k:02d}", call / ".stage" / f"call-{k:02d}")
        done = subprocess.run(
            ["bash", "tools/device_receive.sh"],
            cwd=call,
            env=os.environ | machine,
            capture_output=True,
            text=True,
        )
        assert done.returncode == (0 if k == plan["parts"] else 3), done.stdout + done.stderr
    unpacked = Path(machine["QDIL_STAGE_SITE"])
    assert (unpacked / "pkg" / "data.bin").read_bytes() == (site / "pkg" / "data.bin").read_bytes()
    assert (unpacked / "pkg" / "__init__.py").read_text() == "VALUE = 1\n"
    again = subprocess.run(
        ["bash", "tools/device_receive.sh"], cwd=call, env=os.environ | machine, text=True,
        capture_output=True,
    )  # fmt: skip
    assert again.returncode == 0 and "staged already" in again.stdout


@pytest.mark.skipif(shutil.which("xz") is None or shutil.which("git") is None, reason="xz, git")
def test_the_check_call_receives_resumes_the_carried_record_then_runs_the_check(
    tmp_path: Path,
) -> None:
    site = tmp_path / "site"
    site.mkdir()
    (site / "marker.txt").write_text("staged\n")
    out = tmp_path / "stage"
    out.mkdir()
    _tool().pack(site, out, room=10**6, plan={"packages": {}})
    call = tmp_path / "call"  # the tree of the call: the repository, one part, a record
    shutil.copytree(ROOT / "tools", call / "tools")
    shutil.copytree(ROOT / "benchmarks", call / "benchmarks")
    shutil.copytree(out / "call-01", call / ".stage" / "call-01")
    (call / ".stage" / "gpu_check").mkdir()
    (call / ".stage" / "gpu_check" / "gpu_check.json").write_text('{"machine": {}}')
    machine = {
        "QDIL_STAGE_STORE": str(tmp_path / "machine" / "store"),
        "QDIL_STAGE_SITE": str(tmp_path / "machine" / "site"),
        "OUT": str(tmp_path / "OUT"),
        "PATH": os.environ["PATH"],
    }
    done = subprocess.run(
        ["bash", "tools/device_check.sh", "60"], cwd=call, env=machine, capture_output=True,
        text=True,
    )  # fmt: skip
    assert (tmp_path / "machine" / "site" / "marker.txt").read_text() == "staged\n"
    kept = tmp_path / "OUT" / "gpu_check" / "gpu_check.json"
    assert kept.read_text() == '{"machine": {}}'  # carried, for the check to resume
    # then the check itself ran (here, without CUDA, it stops at once, saying so)
    assert done.returncode == 2 and "--device cuda: torch finds no CUDA device" in done.stderr
    # options after the budget go to the check as they are
    done = subprocess.run(
        ["bash", "tools/device_check.sh", "60", "--no-such-option"], cwd=call, env=machine,
        capture_output=True, text=True,
    )  # fmt: skip
    assert done.returncode == 2 and "unrecognized arguments: --no-such-option" in done.stderr
