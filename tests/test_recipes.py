"""Every recipe is current with recipes/generate.py and parses into a run configuration."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from qdil.cli import fit_parser, parse_fit
from qdil.qd import VPPO, ESGradients

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
    "gail_ebc",
    "diffail",
    "diffail_ebc",
    "mcwae_ebc",
)
# recipes of rewards from plugin packages, which the README's test command installs
PLUGINS = {"diffail": "qdil_diffail"}


def needs_plugin(recipe: Path) -> str | None:
    """The plugin module a recipe's reward comes from, if any."""
    reward = yaml.safe_load(recipe.read_text()).get("reward")
    name = reward.get("class_path") if isinstance(reward, dict) else reward
    return PLUGINS.get(name)


def installed(recipe: Path) -> bool:
    """Whether the recipe's reward is available here (a built-in, or its plugin installed)."""
    module = needs_plugin(recipe)
    return module is None or importlib.util.find_spec(module) is not None


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
    module = needs_plugin(recipe)
    if module:
        pytest.importorskip(module, reason=f"the plugin of {recipe.name} is not installed")
    config, _, _ = parse_fit([str(recipe)])
    init = fit_parser().instantiate(config)
    if "sep_cma_mae" in recipe.stem:  # gradient-free emitters: no estimator
        assert init.rl is None
    else:
        assert isinstance(init.rl, ESGradients if recipe.stem.endswith("_es") else VPPO)
    model = init.reward(17, 6, 2)
    assert model.name
    if "paper" in recipe.parts:
        assert init.qd.iterations == 2000
        assert init.env.num_envs == 3000
    if recipe.stem.endswith("_ebc"):  # the public EBC runners' bonus: q = 2, p = 0
        assert (init.bonus.enabled, init.bonus.type, init.bonus.weight) == (True, "ebc", 2.0)
        assert init.bonus.offset == 0.0
    else:
        assert init.bonus.type == "single_step"


@pytest.mark.parametrize("task", ["walker", "halfcheetah", "humanoid"])
def test_imitation_recipes_read_a_shipped_set_of_their_task(task: str) -> None:
    from qdil.demos.io import load_demos

    for recipe in filter(installed, (ROOT / "recipes").rglob(f"{task}_*.yaml")):
        config, _, _ = parse_fit([str(recipe)])
        if config.demos.path is None:
            continue
        demos = load_demos(config.demos.path, task=config.env.task)
        assert demos.num_episodes == 4, recipe


def test_the_recipes_page_shows_the_flagship_recipe_as_it_is() -> None:
    """docs/concepts/recipes.md's first YAML block is recipes/walker_mcwae.yaml, comments aside."""
    page = (ROOT / "docs" / "concepts" / "recipes.md").read_text()
    block = page.split("```yaml\n", 1)[1].split("```", 1)[0]
    flagship = ROOT / "recipes" / "walker_mcwae.yaml"
    assert yaml.safe_load(block) == yaml.safe_load(flagship.read_text())


def generator():
    """recipes/generate.py as a module (it imports its neighbour ``baselines``)."""
    sys.path.insert(0, str(ROOT / "recipes"))
    try:
        spec = importlib.util.spec_from_file_location("generate", ROOT / "recipes" / "generate.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(ROOT / "recipes"))
    return module


def the_way_back(text: str) -> list[str]:
    """The overrides a recipe's header gives to run it without the fall setting."""
    lines = text.split("Without it (", 1)[1].splitlines()[1:]
    return " ".join(line[2:] for line in lines if line.startswith("# --")).split()


def test_each_fall_recipe_comes_back_to_the_recipe_without_it_as_its_header_says(
    monkeypatch, tmp_path
) -> None:
    """The WQDIL recipes of tasks that end on a fall carry the absorbing and clip setting;
    the overrides their header names give exactly the recipe as it was without it."""
    generate = generator()
    ours = generate.files() | generate.gpu_files() | generate.cvt_files()
    monkeypatch.setattr(generate, "FALL_TASKS", set())
    before = generate.files() | generate.gpu_files() | generate.cvt_files()
    changed = {path for path in ours if ours[path] != before[path]}
    stems = {path.relative_to(ROOT / "recipes").as_posix() for path in changed}
    assert stems == {
        f"{folder}{task}_{method}.yaml"
        for task in ("walker", "humanoid")
        for folder, methods in (
            ("", ("mcwae", "mcwae_wgail", "mcwae_ebc", "mcwae_cvt")),
            ("paper/", ("mcwae", "mcwae_wgail", "mcwae_ebc")),
            ("gpu/", ("mcwae",)),
        )
        for method in methods
    }

    def dumped(argv: list[str]) -> dict:
        config, _, _ = parse_fit(argv)
        return yaml.safe_load(fit_parser().dump(config, skip_unset=False))

    for path in sorted(changed):
        reward = yaml.safe_load(ours[path])["reward"]["init_args"]
        assert (reward["absorbing"], reward["feature_clip"]) == ("floor", 10.0), path
        back = the_way_back(ours[path])
        plain = tmp_path / path.name
        plain.write_text(before[path])
        assert dumped([str(path), *back]) == dumped([str(plain)]), path
