"""``qd.env_steps``: a run stops at the first iteration boundary past its budget in env steps,
checkpoints there, resumes to a larger budget as an unbroken run would, and reads as finished."""

from __future__ import annotations

from pathlib import Path

import pytest

from qdil.cli import main
from qdil.evaluation.runs import collect_runs
from qdil.qd.checkpoint import CHECKPOINT, read_checkpoint
from tests.cli.test_reproducible_runs import archives, metrics, same_archives
from tests.commands import SMOKE

ROOT = Path(__file__).resolve().parents[2]
LONG = ["--qd.iterations", "50", "--logging.checkpoint_every", "10"]


def steps(run_dir: Path) -> list[float]:
    return [float(row["perf/env_steps"]) for row in metrics(run_dir)]


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run to a budget past iteration 1, resumed to one past iteration 2; one unbroken."""
    root = tmp_path_factory.mktemp("budget")
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(root)
        patch.delenv("QDIL_PLUGIN_PATH", raising=False)
        main(["fit", str(SMOKE), *LONG, "--qd.env_steps", "1", "--name", "probe"])
        first = steps(root / "runs" / "probe")[0]  # env steps of one iteration
        budget = str(int(first) + 1)
        main(["fit", str(SMOKE), *LONG, "--qd.env_steps", budget, "--name", "resumed"])
        main(["fit", "--resume", "runs/resumed", "--qd.env_steps", str(int(2 * first) + 2)])
        main(
            [
                "fit",
                str(SMOKE),
                *LONG,
                "--qd.env_steps",
                str(int(2 * first) + 2),
                "--name",
                "unbroken",
            ]
        )
    return root / "runs"


def test_a_run_stops_at_the_first_iteration_past_its_budget(runs: Path) -> None:
    assert len(steps(runs / "probe")) == 1  # 1 step: one iteration, not qd.iterations
    done = steps(runs / "unbroken")
    assert len(done) < 50 and done[-2] < int(2 * done[0]) + 2 <= done[-1]
    checkpoint = read_checkpoint(runs / "unbroken" / CHECKPOINT)
    assert checkpoint["iteration"] == len(done)  # saved at the stop, not at iteration 10


def test_a_run_resumed_to_a_larger_budget_equals_the_unbroken_run(runs: Path) -> None:
    assert metrics(runs / "resumed") == metrics(runs / "unbroken")
    assert same_archives(archives(runs / "resumed"), archives(runs / "unbroken"))


def test_a_run_at_its_budget_is_finished(runs: Path, capsys, monkeypatch) -> None:
    monkeypatch.chdir(runs.parent)
    main(["fit", "--resume", "runs/unbroken"])
    said = capsys.readouterr().err.strip().splitlines()[-1]
    assert "is finished: iteration" in said and "env steps of a budget of" in said
    assert not any(run.unfinished for run in collect_runs([runs]))


def test_a_budget_below_one_is_refused(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit, match=r"qd\.env_steps must be at least 1, got 0"):
        main(["fit", str(SMOKE), "--qd.env_steps", "0"])
