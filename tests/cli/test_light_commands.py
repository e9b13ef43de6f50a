"""Light commands start light: which packages each loads in a process of its own.

Lightning, pyribs and torch cost a ``qdil`` process seconds of imports before it does
anything (docs/testing.md). Commands that train nothing must not pay for them: the test
reads the modules a fresh process has loaded after the command, not its time.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from qdil.cli import COMMANDS, main
from tests.commands import SMOKE, user_env

HEAVY = ("torch", "lightning", "ribs", "wandb", "ray", "sklearn", "pandas", "matplotlib")
"""Packages that each cost a process a second or more to import."""

DRIVER = r"""
import json, sys
from qdil.cli import main
for args in json.loads(sys.argv[1]):
    try:
        main(args)
    except SystemExit:
        pass
print("\nLOADED " + json.dumps(sorted({name.split(".")[0] for name in sys.modules})))
"""


def loaded(commands: list[list[str]], cwd: Path) -> set[str]:
    """Top-level packages a fresh process holds after running ``qdil`` with each argument list."""
    done = subprocess.run(
        [sys.executable, "-c", DRIVER, json.dumps(commands)],
        cwd=cwd,
        env=user_env(),
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    return set(json.loads(done.stdout.rpartition("\nLOADED ")[2]))


def test_help_and_version_load_none_of_the_heavy_packages(tmp_path: Path) -> None:
    light = [["--help"], ["--version"]] + [[c, "--help"] for c in sorted(COMMANDS) if c != "fit"]
    assert loaded(light, tmp_path).isdisjoint(HEAVY)


def test_a_misspelt_recipe_key_is_refused_before_the_heavy_packages(tmp_path: Path) -> None:
    """The recipe's sections and keys are read from source (qdil.recipe_schema)."""
    recipe = tmp_path / "typo.yaml"
    recipe.write_text(SMOKE.read_text().replace("num_envs:", "num_env:"))
    modules = loaded([["fit", str(recipe)], ["fit", str(SMOKE), "--qd.iteratons", "1"]], tmp_path)
    assert modules.isdisjoint(HEAVY), modules & set(HEAVY)
    assert not (tmp_path / "runs").exists()


def test_listing_the_reward_models_loads_none_of_the_heavy_packages(tmp_path: Path) -> None:
    """``qdil rewards list`` reads the models' source (built-ins, entry points, ./plugins)."""
    (tmp_path / "plugins").mkdir()
    (tmp_path / "plugins" / "local.py").write_text(
        "from qdil.rewards import RewardModel, register_reward\n\n\n"
        '@register_reward("local")\nclass Local(RewardModel):\n    """A local reward."""\n'
    )
    modules = loaded([["rewards", "list"]], tmp_path)
    assert modules.isdisjoint(HEAVY), modules & set(HEAVY)


def test_version_prints_the_package_version(capsys) -> None:
    from qdil import __version__

    main(["--version"])
    assert capsys.readouterr().out == f"qdil {__version__}\n"


@pytest.fixture(scope="module")
def finished(smoke_run: Path) -> Path:
    """The folder holding ``runs/tiny``, a finished one-iteration smoke run (the suite's)."""
    return smoke_run.parents[1]


@pytest.mark.parametrize(
    "command",
    [
        ["report", "runs/tiny", "--out", "report", "--videos", "1"],
        ["eval", "runs/tiny", "--episodes", "1"],  # each sweep trial's re-scoring
    ],
    ids=["report", "eval"],
)
def test_reading_finished_runs_loads_no_lightning_wandb_or_ray(finished, command) -> None:
    """Reports and re-scoring read records and play elites (torch and pyribs), never a reward
    model."""
    modules = loaded([command], finished)
    assert (finished / "runs" / "tiny" / "eval.json").is_file() or command[0] != "eval"
    assert (finished / "report" / "report.md").is_file() or command[0] != "report"
    assert modules.isdisjoint({"lightning", "wandb", "ray"}), modules & {"lightning", "wandb"}


def test_a_run_without_wandb_or_ray_loads_neither(tmp_path: Path) -> None:
    """W&B loads only when a run logs to it, Ray only for the Ray executor or a sweep."""
    fit = ["fit", str(SMOKE), "--qd.iterations", "1", "--logging.wandb", "disabled"]
    modules = loaded([[*fit, "--name", "plain"]], tmp_path)
    assert (tmp_path / "runs" / "plain" / "metrics.csv").is_file()
    assert modules.isdisjoint({"wandb", "ray"}), modules & {"wandb", "ray"}
