"""The reward-plugin guide works: docs/guides/example_reward.py as a local plugin.

The example file is copied into a fresh folder on ``$QDIL_PLUGIN_PATH`` and discovered in an
isolated copy of the registry (as ``clean_registry`` in test_registry.py does). The data are
the separable synthetic transitions of test_contract.py: expert around +2, policy around -2.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from qdil.data import TransitionBatch
from qdil.rewards import registry
from qdil.rewards.contract import ACT, CHECKS, OBS, K, as_rollout, demos_of, synthetic, train

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "docs" / "guides" / "example_reward.py"
NAME = "lsgail"


@pytest.fixture
def plugin_folder(monkeypatch, tmp_path) -> Path:
    """A plugin folder holding a copy of the guide's example, discovered in a clean registry."""
    folder = tmp_path / "my_plugins"
    folder.mkdir()
    shutil.copy(EXAMPLE, folder / EXAMPLE.name)
    # register the built-ins globally first: the copy below must hold them, since an import
    # that happens only while the copy is patched in registers into the copy alone
    registry.discover()
    without = {name: entry for name, entry in registry._REGISTRY.items() if name != NAME}
    monkeypatch.setattr(registry, "_REGISTRY", without)
    monkeypatch.setattr(registry, "_discovered", False)
    for name in [m for m in sys.modules if m.startswith(registry.LOCAL_PACKAGE)]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setenv("QDIL_PLUGIN_PATH", str(folder))
    registry.discover(force=True)
    yield folder
    # forget the modules imported from the tmp folder; monkeypatch then restores the old ones
    for name in [m for m in sys.modules if m.startswith(registry.LOCAL_PACKAGE)]:
        del sys.modules[name]


@pytest.fixture(scope="module")
def expert() -> TransitionBatch:
    return synthetic(2.0, 400, seed=1)


@pytest.fixture(scope="module")
def policy() -> TransitionBatch:
    return synthetic(-2.0, 400, seed=2)


def trained(expert: TransitionBatch, policy: TransitionBatch, updates: int):
    """The registered example, set up as the QD loop does, after ``updates``."""
    torch.manual_seed(0)
    return train(registry.get_reward(NAME)(OBS, ACT, K), expert, policy, updates)


def test_the_example_registers_from_the_local_plugin_folder(plugin_folder) -> None:
    entry = {e.name: e for e in registry.list_rewards()}[NAME]
    assert entry.source == f"local plugin {plugin_folder / EXAMPLE.name}"
    assert entry.cls.__module__ == f"{registry.LOCAL_PACKAGE}.example_reward"
    assert entry.cls.__qualname__ == "LeastSquaresGAIL"
    assert entry.description.startswith("least-squares discriminator")
    assert registry.get_reward(NAME) is entry.cls
    assert entry.cls.learned and entry.cls.needs_demos and entry.cls.prefers_expert


def test_the_example_learns_to_prefer_expert_transitions(plugin_folder, expert, policy) -> None:
    model, metrics = trained(expert, policy, updates=40)
    assert set(metrics[-1]) == {"loss", "gp", "expert_score", "policy_score"}
    assert all(math.isfinite(v) for m in metrics for v in m.values())
    assert metrics[-1]["loss"] < metrics[0]["loss"]
    assert metrics[-1]["expert_score"] > 0 > metrics[-1]["policy_score"]
    held_out_e, held_out_p = synthetic(2.0, 200, seed=5), synthetic(-2.0, 200, seed=6)
    r_e = model.predict_reward(as_rollout(held_out_e, envs=2))
    r_p = model.predict_reward(as_rollout(held_out_p, envs=2))
    assert r_e.shape == r_p.shape == (100, 2)
    assert r_e.dtype == torch.float32
    assert bool(((r_e >= 0) & (r_e <= 1)).all()) and bool(((r_p >= 0) & (r_p <= 1)).all())
    assert r_e.mean() > r_p.mean() + 0.5, f"expert {r_e.mean():.3f}, policy {r_p.mean():.3f}"


def test_the_example_state_survives_a_checkpoint_round_trip(plugin_folder, expert, policy) -> None:
    model, _ = trained(expert, policy, updates=3)
    rollout = as_rollout(policy, envs=2)
    expected = model.predict_reward(rollout, update=True)
    state, extra = model.state_dict(), model.extra_state()
    torch.manual_seed(1)  # a fresh model with other weights
    copy = registry.get_reward(NAME)(OBS, ACT, K)
    assert not torch.allclose(copy.predict_reward(rollout), expected)
    copy.setup(demos_of(expert))
    copy.load_state_dict(state)
    copy.load_extra_state(extra)
    torch.testing.assert_close(copy.predict_reward(rollout, update=True), expected)


def test_the_guide_command_line_picks_the_plugin(plugin_folder) -> None:
    from qdil.cli import parse_fit

    recipe = str(REPO / "recipes" / "walker_mcwae.yaml")
    config, _, _ = parse_fit([recipe, "--reward", NAME, "--bonus.enabled", "false"])
    assert config.reward.class_path == f"{registry.LOCAL_PACKAGE}.example_reward.LeastSquaresGAIL"
    assert config.reward.init_args.batch_size == 120  # kept from the recipe's mcwae_wgail args
    assert config.bonus.enabled is False


@pytest.mark.parametrize("how", ["registered", "class", "path", "the guide's"])
def test_reward_help_lists_the_plugins_options(how, plugin_folder, capsys) -> None:
    from qdil.cli import main

    if how == "the guide's":
        guide = (REPO / "docs" / "guides" / "write-a-reward-plugin.md").read_text()
        value = guide.split("--reward.help ", 1)[1].split()[0]
    else:
        value = {
            "registered": NAME,
            "class": "LeastSquaresGAIL",
            "path": f"{registry.LOCAL_PACKAGE}.example_reward.LeastSquaresGAIL",
        }[how]
    with pytest.raises(SystemExit) as stopped:
        main(["fit", "--reward.help", value])
    assert stopped.value.code in (0, None)
    out = capsys.readouterr().out
    assert "--reward.hidden" in out and "--reward.gp_weight" in out


def guide_block(start: str) -> str:
    """The fenced block of the plugin guide that begins with ``start``."""
    guide = (REPO / "docs" / "guides" / "write-a-reward-plugin.md").read_text()
    return start + guide.split(f"\n{start}", 1)[1].split("```", 1)[0]


def test_the_guide_real_recipe_is_the_flagship_with_lsgail(plugin_folder, tmp_path) -> None:
    """Section 4's walker_lsgail.yaml: recipes/walker_mcwae.yaml --reward lsgail, no bonus."""
    import yaml

    from qdil.cli import fit_parser, parse_fit

    recipe = tmp_path / "walker_lsgail.yaml"
    recipe.write_text(guide_block("```yaml\n# walker_lsgail.yaml").split("\n", 1)[1])
    flagship = str(REPO / "recipes" / "walker_mcwae.yaml")
    ours, _, stem = parse_fit([str(recipe)])
    swapped, _, swapped_stem = parse_fit([flagship, "--reward", NAME, "--bonus.enabled", "false"])
    assert stem == swapped_stem == "walker_lsgail"  # the run directory the guide names
    dumped = [yaml.safe_load(fit_parser().dump(c, skip_unset=False)) for c in (ours, swapped)]
    for config in dumped:
        assert config["bonus"].pop("enabled") is False
        config["bonus"].pop("weight")  # the flagship's 0.25, unused without the bonus
    assert dumped[0] == dumped[1]
    wide, _, _ = parse_fit(
        [str(recipe), "--reward.hidden", "[128, 128]", "--reward.gp_weight", "5"]
    )
    assert (wide.reward.init_args.hidden, wide.reward.init_args.gp_weight) == ([128, 128], 5.0)


def test_the_guide_runs_without_a_source_checkout() -> None:
    """Its commands use only the files it writes: nothing from recipes/ or docs/."""
    guide = (REPO / "docs" / "guides" / "write-a-reward-plugin.md").read_text()
    commands = [block.split("```", 1)[0] for block in guide.split("```bash\n")[1:]]
    assert commands
    for block in commands:
        assert "recipes/" not in block and "docs/" not in block, block
    assert "mkdir -p my-qdil/plugins" in commands[0]
    saved = "<!-- save-as: plugins/example_reward.py -->"  # the docs test saves it there too
    assert f"Save this as `plugins/example_reward.py`:\n\n{saved}\n```python\n" in guide
    for written in ("smoke.yaml", "walker_lsgail.yaml"):
        assert f"```yaml\n# {written}:" in guide


def test_the_contract_checks_pass_for_the_example(plugin_folder, tmp_path) -> None:
    """The guide's test step, run outside the source tree: it needs only the installed qdil."""
    env = {**os.environ, "QDIL_PLUGIN_PATH": str(plugin_folder)}
    command = [sys.executable, "-m", "qdil.rewards.contract", NAME]
    done = subprocess.run(
        command, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert done.stdout.count(f"PASS {NAME} ") == len(CHECKS), done.stdout


def test_the_guide_smoke_recipe_trains_the_example(plugin_folder, tmp_path, monkeypatch) -> None:
    """Section 4's quick check: the guide's smoke.yaml with the shipped Walker2d demos."""
    from qdil.cli import main

    guide = (REPO / "docs" / "guides" / "write-a-reward-plugin.md").read_text()
    recipe = guide.split("```yaml\n# smoke.yaml", 1)[1].split("```", 1)[0]
    (tmp_path / "smoke.yaml").write_text(f"# smoke.yaml{recipe}")
    monkeypatch.chdir(tmp_path)
    main(["fit", "smoke.yaml", "--demos.path", "walker2d", "--name", "lsgail-smoke"])
    last = (tmp_path / "runs" / "lsgail-smoke" / "metrics.csv").read_text().splitlines()
    header = last[0].split(",")
    assert last[-1].split(",")[header.index("iteration")] == "2"
    assert {"reward/loss", "reward/gp"} <= set(header)


def test_the_guide_shows_the_example_file_verbatim() -> None:
    guide = (REPO / "docs" / "guides" / "write-a-reward-plugin.md").read_text()
    assert f"```python\n{EXAMPLE.read_text().rstrip()}\n```" in guide
