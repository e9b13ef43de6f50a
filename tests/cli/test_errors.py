"""First contact through the real command line: every --help, and bad inputs as clear errors.

Each bad input must exit non-zero with a short message (no traceback) that names the field,
file or value, and a bad recipe must be refused before a run directory exists.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.commands import SMOKE, cli

ROOT = Path(__file__).resolve().parents[2]


HELP = {
    "qdil": ([], "fit,render,report,rewards"),
    "qdil --help": (["--help"], "COMMAND --help"),
    "fit": (["fit", "--help"], "--qd.iterations"),
    "fit -h after a recipe": (["fit", str(SMOKE), "-h"], "--logging.checkpoint_every"),
    "fit --reward.help NAME": (["fit", "--reward.help", "gail"], "--reward.gp_weight"),
    "fit --reward.help CLASS": (["fit", "--reward.help", "GAIL"], "--reward.gp_weight"),
    "fit --reward.help PATH": (
        ["fit", "--reward.help=qdil.rewards.builtin.GAIL"],
        "--reward.gp_weight",
    ),
    "rewards": (["rewards", "--help"], "list"),
    "rewards list": (["rewards", "list", "--help"], "description and source"),
    "eval": (["eval", "--help"], "--episodes"),
    "report": (["report", "--help"], "--out"),
    "demos": (["demos", "--help"], "--top"),
    "render": (["render", "--help"], "--cell"),
}


@pytest.mark.parametrize(("args", "option"), list(HELP.values()), ids=list(HELP))
def test_every_help_exits_0_and_lists_options(
    args: list[str], option: str, capsys, monkeypatch, tmp_path: Path
) -> None:
    monkeypatch.chdir(tmp_path)
    code, out, err = cli(args, capsys)
    assert code == 0, err
    assert option in out
    if not args or args[-1] in ("--help", "-h"):
        assert "usage:" in out
    markup = [line for line in out.splitlines() if "``" in line or line.rstrip().endswith("::")]
    assert not markup, f"reStructuredText in the help: {markup}"
    assert out.count("quality-diversity imitation learning") <= 1, "description printed twice"


def test_help_of_the_light_commands_imports_no_torch() -> None:
    """`qdil --help` answers at once: no torch, Lightning or pyribs before a command needs them."""
    script = (
        "import sys\n"
        "from qdil.cli import main\n"
        "for args in ([], ['--help'], ['eval', '--help'], ['report', '--help'],\n"
        "             ['demos', '--help'], ['rewards', '--help'], ['render', '--help']):\n"
        "    try:\n"
        "        main(args)\n"
        "    except SystemExit as exit_:\n"
        "        assert not exit_.code, (args, exit_.code)\n"
        "heavy = [m for m in ('torch', 'lightning', 'ribs', 'jsonargparse') if m in sys.modules]\n"
        "assert not heavy, heavy\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120, check=False
    )
    assert done.returncode == 0, done.stderr[-2000:]


@pytest.fixture
def demo_files(walker_demos: Path, tmp_path: Path) -> dict[str, Path]:
    """Demonstration files whose header disagrees with their arrays, or names no task."""
    data = dict(np.load(walker_demos))
    header = json.loads(str(data["header"]))
    files = {}
    for name, change in {"obs_dim": {"obs_dim": 18}, "task": {"task": "Nosuch-v9"}}.items():
        files[name] = tmp_path / f"bad_{name}.npz"
        np.savez(files[name], **{**data, "header": np.array(json.dumps({**header, **change}))})
    return files


BAD_EMITTER = """\
reward: true_reward
env: {task: Walker2d-v5}
qd:
  emitter:
    class_path: nosuch_module.Emitter
"""

# (arguments, words the message must hold); {smoke}, {empty}, {file}, {bad_recipe},
# {bad_obs_dim} and {bad_task} are filled in by the test
CASES = {
    "iterations -1": (
        ["fit", "{smoke}", "--qd.iterations", "-1"],
        ["qd.iterations must be at least 1, got -1"],
    ),
    "iterations 0": (
        ["fit", "{smoke}", "--qd.iterations", "0"],
        ["qd.iterations must be at least 1, got 0"],
    ),
    "cells 0": (["fit", "{smoke}", "--qd.cells", "0"], ["qd.cells must be at least 1, got 0"]),
    "checkpoint_every 0": (
        ["fit", "{smoke}", "--logging.checkpoint_every", "0"],
        ["logging.checkpoint_every must be at least 1, got 0"],
    ),
    "seed -5": (["fit", "{smoke}", "--seed", "-5"], ["seed must be at least 0, got -5"]),
    "bonus type unknown": (
        ["fit", "{smoke}", "--bonus.type", "count"],
        ['"bonus.type"', "single_step", "ebc", "count"],
    ),
    "bonus cells under ebc": (
        ["fit", "{smoke}", "--bonus.type", "ebc", "--bonus.cells", "4"],
        ["bonus.cells applies to bonus.type single_step only", "got 4"],
    ),
    "bonus offset under single_step": (
        ["fit", "{smoke}", "--bonus.offset", "1"],
        ["bonus.offset applies to bonus.type ebc only", "got 1.0"],
    ),
    "bonus in_fitness under ebc": (
        ["fit", "{smoke}", "--bonus.type", "ebc", "--bonus.in_fitness", "false"],
        ["bonus.in_fitness applies to bonus.type single_step only"],
    ),
    "reward class name unknown": (
        ["fit", "{smoke}", "--reward", "Gial"],
        ["unknown reward model 'Gial'; registered: airl"],
    ),
    "reward.help class name unknown": (
        ["fit", "--reward.help", "Gial"],
        ["--reward.help", "unknown reward model 'Gial'; registered: airl"],
    ),
    "recipe is a directory": (["fit", "{empty}"], ["{empty}", "is a directory"]),
    "emitter in a missing module (recipe)": (
        ["fit", "{bad_recipe}"],
        ["qd.emitter", "nosuch_module.Emitter", "no module named 'nosuch_module'"],
    ),
    "emitter in a missing module (flag)": (
        ["fit", "{smoke}", "--qd.emitter.class_path", "nosuch_module.Emitter"],
        ["qd.emitter", "no module named 'nosuch_module'"],
    ),
    "resume of a file": (["fit", "--resume", "{file}"], ["{file}", "not a qdil run directory"]),
    "eval of an empty directory": (["eval", "{empty}"], ["{empty}", "no config.yaml"]),
    "eval of a file": (["eval", "{file}"], ["{file}", "is a file, not a run directory"]),
    "eval episodes 0": (["eval", "{empty}", "--episodes", "0"], ["--episodes", "got 0"]),
    "demos top 0": (["demos", "{empty}", "--top", "0", "--out", "x.npz"], ["--top", "got 0"]),
    "demos of an empty directory": (
        ["demos", "{empty}", "--out", "x.npz"],
        ["{empty}", "no config.yaml"],
    ),
    "report with no run": (
        ["report", "{empty}", "--out", "report"],
        ["no run could be included"],
    ),
    "demos --info, header obs_dim": (
        ["demos", "--info", "{bad_obs_dim}"],
        ["{bad_obs_dim}", "obs has 17 columns", "obs_dim = 18"],
    ),
    "demos --info, unknown task": (
        ["demos", "--info", "{bad_task}"],
        ["{bad_task}", "'Nosuch-v9'", "known tasks: Walker2d-v5"],
    ),
}


@pytest.mark.parametrize(("args", "words"), list(CASES.values()), ids=list(CASES))
def test_bad_inputs_are_clear_errors(
    args: list[str],
    words: list[str],
    demo_files: dict[str, Path],
    capsys,
    monkeypatch,
    tmp_path: Path,
) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("QDIL_PLUGIN_PATH", raising=False)  # only ./plugins, absent here
    (tmp_path / "empty").mkdir()
    (tmp_path / "file").write_text("not a run\n")
    (tmp_path / "bad.yaml").write_text(BAD_EMITTER)
    names = {
        "smoke": str(SMOKE),
        "empty": "empty",
        "file": "file",
        "bad_recipe": "bad.yaml",
        "bad_obs_dim": str(demo_files["obs_dim"]),
        "bad_task": str(demo_files["task"]),
    }
    code, _, err = cli([arg.format(**names) for arg in args], capsys)
    assert code != 0
    for word in words:
        assert word.format(**names) in err, err
    assert "Traceback" not in err and len(err.splitlines()) <= 8, err
    if args[0] == "eval":
        assert "num_envs" not in err  # the user's flag, not an internal name
    assert not (tmp_path / "runs").exists(), "a refused recipe must leave no run directory"


@pytest.fixture
def broken_plugins(monkeypatch) -> Path:
    """tests/cli/broken_plugins as the plugin folder, discovered in a copy of the registry."""
    from qdil.rewards import registry

    folder = Path(__file__).parent / "broken_plugins"
    registry.discover()  # built-ins first, so the copy below holds them
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    monkeypatch.setattr(registry, "_discovered", False)
    for name in [m for m in sys.modules if m.startswith(registry.LOCAL_PACKAGE)]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setenv("QDIL_PLUGIN_PATH", str(folder))
    yield folder
    # forget the broken modules; monkeypatch then restores the registry and the old modules
    for name in [m for m in sys.modules if m.startswith(registry.LOCAL_PACKAGE)]:
        del sys.modules[name]


PLUGIN = "qdil_local_plugins.broken_rewards"

# "reward model [flags]" -> (words the message must hold, whether a run directory may be left)
BROKEN_PLUGINS = {
    "no_reward_method": (
        [f"reward model no_reward_method ({PLUGIN}.NoRewardMethod)", "implement reward(batch)"],
        False,
    ),
    "no_update_method": (
        [f"({PLUGIN}.NoUpdateMethod)", "implement update(expert, policy, iteration);"],
        False,
    ),
    "no_learning_methods": (
        [
            "not implement configure_optimizers() and update(expert, policy, iteration)",
            "or set learned = False",
        ],
        False,
    ),
    # the run started: it is left for `qdil fit --resume` once the model is fixed
    "nan_fixed": (
        [
            f"reward model nan_fixed ({PLUGIN}.NaNFixed): non-finite rewards at QD iteration 1",
            "not trained online, so check reward()",
            "qdil fit --resume runs/nan_fixed",
        ],
        True,
    ),
    "nan_untrained": (
        [f"({PLUGIN}.NaNUntrained)", "iteration 1", "before its first update"],
        True,
    ),
    "nan_after_update": (
        ["non-finite rewards at QD iteration 2", "diverged: lower its learning rate"],
        True,
    ),
    # the exploration bonus wraps the model: the message still names the model that failed
    "nan_fixed --bonus.enabled true": (
        [f"reward model nan_fixed ({PLUGIN}.NaNFixed): non-finite rewards", "not trained"],
        True,
    ),
}


@pytest.mark.parametrize(
    ("reward", "expected"), list(BROKEN_PLUGINS.items()), ids=list(BROKEN_PLUGINS)
)
def test_broken_reward_plugins_are_clear_errors(
    reward: str, expected: tuple[list[str], bool], broken_plugins, capsys, monkeypatch, tmp_path
) -> None:
    """An incomplete plugin is refused before training; NaN rewards stop it with advice."""
    words, leaves_run = expected
    reward, *flags = reward.split()
    monkeypatch.chdir(tmp_path)
    code, _, err = cli(["fit", str(SMOKE), "--reward", reward, "--name", reward, *flags], capsys)
    assert code != 0
    for word in words:
        assert word in err, err
    assert "Traceback" not in err and len(err.splitlines()) <= 8, err
    if not leaves_run:  # refused with the recipe: nothing built, nothing trained
        assert not (tmp_path / "runs").exists()
    if reward.startswith("nan") and reward != "nan_fixed":
        assert "not trained online" not in err  # the advice fits a learned model
    if reward == "nan_fixed":
        assert "learning rate" not in err  # nothing to lower for a fixed reward


def test_an_incomplete_model_is_refused_at_construction(broken_plugins) -> None:
    """Code that builds a model without the command line gets the same error, not a late one."""
    from qdil.rewards import get_reward
    from qdil.rewards.base import RewardContractError

    with pytest.raises(RewardContractError, match=r"NoRewardMethod\) does not implement reward"):
        get_reward("no_reward_method")(5, 2, 2)
