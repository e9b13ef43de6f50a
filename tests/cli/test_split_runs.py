"""A run's numbers do not depend on how its work is split: Ray workers against the local run,
and ``qdil eval`` with three batch sizes, as a user starts them (``qdil`` processes with a real
run's thread settings: physics and torch on every core here, one thread per Ray worker).

On an AMD EPYC with AVX-512 the Ray run differed from the local run from the first
iteration on, and ``qdil eval`` with another ``--batch`` gave other returns, until policy
inference computed every row alone (``qdil.rl.inference``; issue 46). A run continued on
another vendor's CPU is reported as not reproducible on one machine."""

from __future__ import annotations

import json
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests import commands
from tests.cli.test_reproducible_runs import archives, metrics, same_archives
from tests.commands import SMOKE, user_env

pytest.importorskip("ray")


def qdil(*args: str, cwd: Path) -> None:
    """``qdil ARGS`` in a process of its own, with the threads a user's run has."""
    env = user_env(threads=False, RAY_DISABLE_USAGE_STATS="1")
    commands.qdil(*args, cwd=cwd, env=env, check=True)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The smoke recipe at its own shapes (6 simulations), locally and on 2 Ray workers."""
    root = tmp_path_factory.mktemp("split")
    qdil("fit", str(SMOKE), "--name", "local", cwd=root)
    ray = ["--executor", "qdil.executors.RayExecutor", "--executor.init_args.num_workers", "2"]
    qdil("fit", str(SMOKE), *ray, "--name", "ray", cwd=root)
    return root / "runs"


def test_two_ray_workers_give_the_local_run(runs: Path) -> None:
    local = metrics(runs / "local")
    assert [row["iteration"] for row in local] == ["1", "2", "3"]
    assert metrics(runs / "ray") == local
    assert same_archives(archives(runs / "ray"), archives(runs / "local"))


def test_qdil_eval_gives_the_same_scores_with_any_batch(runs: Path, tmp_path: Path) -> None:
    found = {}
    for batch in ("1", "3", "64"):
        qdil("eval", str(runs / "local"), "--episodes", "2", "--batch", batch, cwd=runs.parent)
        summary = json.loads((runs / "local" / "eval.json").read_text())
        corrected = pickle.loads((runs / "local" / "corrected_archive.pkl").read_bytes()).data()
        summary.pop("provenance")
        found[batch] = (summary, corrected)
    (first, archive), *others = found.values()
    assert first["elites_evaluated"] > 3  # more elites than the smaller batches hold
    for summary, other in others:
        assert summary == first
        assert all(np.array_equal(archive[key], other[key]) for key in archive)


def test_a_run_continued_on_another_cpu_vendor_is_reported_as_such(
    runs: Path, tmp_path: Path
) -> None:
    from qdil.evaluation.report import write_report

    mixed = Path(shutil.copytree(runs / "local", tmp_path / "runs" / "mixed"))
    starts = json.loads((mixed / "provenance.json").read_text())
    other = "GenuineIntel" if starts[0]["cpu_vendor"] == "AuthenticAMD" else "AuthenticAMD"
    starts.append({**starts[0], "from_iteration": 2, "cpu_vendor": other})
    (mixed / "provenance.json").write_text(json.dumps(starts))
    report = write_report([mixed, runs / "ray"], tmp_path / "out")
    said = "not reproducible bit for bit on one machine"
    notes = {run.path.name: run.notes for run in report.runs}
    assert any(said in note for note in notes["mixed"])
    assert not any(said in note for note in notes["ray"])
    assert said in (tmp_path / "out" / "report.md").read_text()
    record = json.loads((tmp_path / "out" / "runs" / "mixed" / "record.json").read_text())
    assert any(said in note for note in record["notes"])
