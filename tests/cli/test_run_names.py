"""A new run's default name says which method ran: reward model and bonus (parsing only)."""

from __future__ import annotations

from pathlib import Path

import pytest

from qdil.cli import parse_fit

ROOT = Path(__file__).resolve().parents[2]
RECIPES = ROOT / "recipes"
FLAGSHIP = str(RECIPES / "walker_mcwae.yaml")
SMOKE_IL = str(ROOT / "recipes" / "smoke" / "walker_il.yaml")


@pytest.mark.parametrize(
    ("argv", "stem"),
    [
        # recipes as they are, or with options of their own model: the names of today
        ([FLAGSHIP], "walker_mcwae"),
        ([FLAGSHIP, "--seed", "3", "--qd.iterations", "1"], "walker_mcwae"),
        ([FLAGSHIP, "--reward.batch_size", "64"], "walker_mcwae"),
        ([FLAGSHIP, "--reward", "mcwae_wgail"], "walker_mcwae"),
        ([FLAGSHIP, "--reward", "qdil.rewards.builtin.MCWAEWGAIL"], "walker_mcwae"),
        ([SMOKE_IL], "walker_il"),
        ([FLAGSHIP, "--bonus.weight", "1.0"], "walker_mcwae"),
        # another model: the recipe's first part, the model's registered name, the bonus
        ([FLAGSHIP, "--reward", "gail", "--bonus.enabled", "false"], "walker_gail"),
        ([FLAGSHIP, "--reward=airl"], "walker_airl_bonus"),  # the flagship's bonus stays on
        ([FLAGSHIP, "--reward", "qdil.rewards.builtin.GAIL"], "walker_gail_bonus"),
        ([FLAGSHIP, "--reward", "gail", "--bonus.type", "ebc"], "walker_gail_ebc"),
        ([SMOKE_IL, "--reward", "pwil"], "walker_pwil"),
        # the bonus switched on, off or to the other type: the name says which runs
        ([FLAGSHIP, "--bonus.enabled", "false"], "walker_mcwae_nobonus"),
        ([FLAGSHIP, "--bonus.type", "ebc"], "walker_mcwae_ebc"),
        ([RECIPES / "walker_gail.yaml", "--bonus.enabled", "true"], "walker_gail_bonus"),
        ([RECIPES / "walker_gail_ebc.yaml", "--bonus.enabled", "false"], "walker_gail"),
        ([RECIPES / "walker_gail_ebc.yaml", "--bonus.type", "single_step"], "walker_gail_bonus"),
        ([SMOKE_IL, "--bonus.enabled", "true"], "walker_il_bonus"),
        # another integrator than the task model's own: not the v5 task, and named so
        ([FLAGSHIP, "--env.integrator", "euler"], "walker_mcwae_euler"),
        ([FLAGSHIP, "--env.integrator", "rk4"], "walker_mcwae"),  # Walker2d's own
        (
            [FLAGSHIP, "--reward", "gail", "--env.integrator=implicitfast"],
            "walker_gail_bonus_implicitfast",
        ),
        ([RECIPES / "halfcheetah_ppga.yaml", "--env.integrator", "euler"], "halfcheetah_ppga"),
        ([RECIPES / "halfcheetah_ppga.yaml", "--env.integrator", "rk4"], "halfcheetah_ppga_rk4"),
    ],
)
def test_the_default_name_follows_the_method_that_runs(argv: list, stem: str) -> None:
    _, _, got = parse_fit([str(arg) for arg in argv])
    assert got == stem


def test_every_shipped_recipe_keeps_its_name() -> None:
    shipped = sorted(RECIPES.rglob("*.yaml"))
    assert len(shipped) > 40
    for recipe in shipped:
        assert parse_fit([str(recipe)])[2] == recipe.stem, recipe


def test_a_recipe_without_underscore_keeps_its_name_in_front(tmp_path: Path) -> None:
    recipe = tmp_path / "smoke.yaml"
    recipe.write_text(Path(SMOKE_IL).read_text())
    assert parse_fit([str(recipe)])[2] == "smoke"
    assert parse_fit([str(recipe), "--reward", "airl"])[2] == "smoke_airl"


def test_the_documented_commands_in_order_make_distinct_runs() -> None:
    """getting-started, recipes.md: the flagship, then another model from the same recipe."""
    first = parse_fit([FLAGSHIP])
    second = parse_fit([FLAGSHIP, "--reward", "gail", "--bonus.enabled", "false"])
    names = {f"{stem}-seed{config.seed}" for config, _, stem in (first, second)}
    assert names == {"walker_mcwae-seed0", "walker_gail-seed0"}


def test_an_explicit_name_wins() -> None:
    config, _, _ = parse_fit([FLAGSHIP, "--reward", "gail", "--name", "mine"])
    assert config.name == "mine"


def test_fit_makes_the_run_directory_under_that_name(tmp_path: Path, monkeypatch) -> None:
    """``qdil fit`` itself: stopped at the build, after the name and directory are chosen."""
    import importlib

    fit_module = importlib.import_module("qdil.cli.fit")
    experiment = importlib.import_module("qdil.experiment")
    seen = {}

    class Built(Exception):
        pass

    def build(init, name, run_dir, resolved, *, resume, tracker=None):
        seen.update(name=name, run_dir=run_dir)
        raise Built

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(experiment, "build_recipe", build)
    with pytest.raises(Built):
        fit_module.fit([FLAGSHIP, "--reward", "gail", "--bonus.enabled", "false"])
    assert seen == {"name": "walker_gail-seed0", "run_dir": Path("runs") / "walker_gail-seed0"}


def test_an_unknown_integrator_is_refused_naming_the_key() -> None:
    with pytest.raises(SystemExit, match="integrator"):
        parse_fit([FLAGSHIP, "--env.integrator", "verlet"])
