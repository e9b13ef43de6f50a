"""Every recipe is current with recipes/generate.py and parses into a run configuration."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from qdil.cli import fit_parser, parse_fit
from qdil.rl.vppo import VPPO

ROOT = Path(__file__).resolve().parents[1]
RECIPES = sorted((ROOT / "recipes").rglob("*.yaml"))
METHODS = (
    "ppga",
    "mcwae",
    "wae_wgail",
    "gail",
    "pwil",
    "airl",
    "maxentirl",
    "giril",
    "mcwae_gail_bonus",
    "wae_gail",
    "wae_wgail_bonus",
    "mcwae_wgail",
)


def test_generated_recipes_are_up_to_date() -> None:
    subprocess.run([sys.executable, str(ROOT / "recipes" / "generate.py"), "--check"], check=True)


def test_the_flagship_and_every_paper_row_have_recipes() -> None:
    names = {p.relative_to(ROOT / "recipes").as_posix() for p in RECIPES}
    for task in ("walker", "halfcheetah", "humanoid"):
        for method in METHODS:
            assert f"{task}_{method}.yaml" in names
            assert f"paper/{task}_{method}.yaml" in names


@pytest.mark.parametrize(
    "recipe", RECIPES, ids=lambda p: p.relative_to(ROOT / "recipes").as_posix()
)
def test_recipe_parses_and_instantiates(recipe: Path) -> None:
    config, _, _ = parse_fit([str(recipe)])
    init = fit_parser().instantiate(config)
    assert isinstance(init.rl, VPPO)
    model = init.reward(17, 6, 2)
    assert model.name
    if "paper" in recipe.parts:
        assert init.qd.iterations == 2000
        assert init.env.num_envs == 3000


@pytest.mark.parametrize("task", ["walker", "halfcheetah"])
def test_imitation_recipes_read_a_shipped_set_of_their_task(task: str) -> None:
    from qdil.demos.io import load_demos

    for recipe in (ROOT / "recipes").rglob(f"{task}_*.yaml"):
        config, _, _ = parse_fit([str(recipe)])
        if config.demos.path is None:
            continue
        demos = load_demos(config.demos.path, task=config.env.task)
        assert demos.num_episodes == 4, recipe


def test_humanoid_recipes_name_the_file_their_header_tells_how_to_make() -> None:
    for recipe in (ROOT / "recipes").rglob("humanoid_*.yaml"):
        config, _, _ = parse_fit([str(recipe)])
        if config.demos.path is not None:
            assert config.demos.path == "humanoid.npz"
            assert "qdil demos runs/humanoid_ppga-seed0 --out humanoid.npz" in recipe.read_text()
