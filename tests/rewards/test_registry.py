"""The reward registry: built-ins, entry points, local plugin folders, duplicates."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from qdil.rewards import get_reward, list_rewards, registry

BUILTINS = {
    "gail",
    "airl",
    "pwil",
    "maxentirl",
    "giril",
    "wae_gail",
    "wae_wgail",
    "mcwae_wgail",
    "mcwae_gail",
    "true_reward",
}


@pytest.fixture
def clean_registry(monkeypatch):
    registry.discover()  # built-ins first, so the copy below holds them
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))
    monkeypatch.setattr(registry, "_discovered", False)
    for name in [m for m in sys.modules if m.startswith(registry.LOCAL_PACKAGE)]:
        monkeypatch.delitem(sys.modules, name)
    return registry


def test_every_built_in_is_registered_with_a_description() -> None:
    entries = {e.name: e for e in list_rewards()}
    assert set(entries) >= BUILTINS
    for name in BUILTINS:
        assert entries[name].source == "qdil (built-in)"
        assert entries[name].description
        assert get_reward(name).name == name


def test_the_example_plugin_registers_through_its_entry_point() -> None:
    pytest.importorskip("qdil_vail", reason="plugins/qdil-vail is not installed")
    entry = {e.name: e for e in list_rewards()}["vail"]
    assert entry.source == "entry point vail (qdil-vail)"


def test_unknown_name_lists_the_registered_ones() -> None:
    # the sorted names, with the diffail plugin between the built-ins where it is installed
    listed = r"unknown reward model 'gial'; registered: airl, (diffail, )?gail"
    with pytest.raises(ValueError, match=listed):
        get_reward("gial")


PLUGIN = '''
from qdil.rewards import RewardModel, register_reward

@register_reward("{name}")
class Local(RewardModel):
    """A local test reward."""
    learned = False
    needs_demos = False
'''


def test_local_plugin_folder_is_discovered(clean_registry, tmp_path, monkeypatch) -> None:
    (tmp_path / "my_reward.py").write_text(PLUGIN.format(name="my_reward"))
    monkeypatch.setenv("QDIL_PLUGIN_PATH", str(tmp_path))
    clean_registry.discover(force=True)
    entry = {e.name: e for e in clean_registry.list_rewards()}["my_reward"]
    assert entry.source == f"local plugin {tmp_path / 'my_reward.py'}"
    assert entry.cls.__module__ == "qdil_local_plugins.my_reward"


def test_plugins_and_the_plugin_path_are_both_scanned(
    clean_registry, tmp_path, monkeypatch
) -> None:
    (tmp_path / "plugins").mkdir()
    (tmp_path / "plugins" / "here.py").write_text(PLUGIN.format(name="here"))
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "there.py").write_text(PLUGIN.format(name="there"))
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("QDIL_PLUGIN_PATH", str(tmp_path / "elsewhere"))
    clean_registry.discover(force=True)
    sources = {e.name: e.source for e in clean_registry.list_rewards()}
    assert sources["here"] == f"local plugin {tmp_path / 'plugins' / 'here.py'}"
    assert sources["there"] == f"local plugin {tmp_path / 'elsewhere' / 'there.py'}"


def test_plugins_on_the_path_too_is_scanned_once(clean_registry, tmp_path, monkeypatch) -> None:
    (tmp_path / "plugins").mkdir()
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv(
        "QDIL_PLUGIN_PATH", os.pathsep.join(["plugins", "", str(tmp_path / "plugins")])
    )
    assert clean_registry.plugin_folders() == [tmp_path / "plugins"]


@pytest.mark.parametrize("kind", ["missing", "file"])
def test_a_plugin_path_folder_that_is_not_there_is_an_error(
    kind, clean_registry, tmp_path, monkeypatch
) -> None:
    """A mistyped folder would otherwise leave its plugins out without a word."""
    folder = tmp_path / "my-plugins"
    if kind == "file":
        folder.write_text("")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("QDIL_PLUGIN_PATH", os.pathsep.join([str(tmp_path), str(folder)]))
    what = "is a file, not a folder" if kind == "file" else "does not exist"
    message = (
        f"QDIL_PLUGIN_PATH names the plugin folder {folder}, which {what}; create it, correct "
        "the path, or take it out of QDIL_PLUGIN_PATH (./plugins is scanned without it)"
    )
    with pytest.raises(FileNotFoundError) as raised:
        clean_registry.discover(force=True)
    assert str(raised.value) == message
    # through the command line: the message, no traceback
    env = {**os.environ, "QDIL_PLUGIN_PATH": str(folder)}
    done = subprocess.run(
        [sys.executable, "-m", "qdil.cli", "rewards", "list"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 1
    assert done.stderr.strip() == f"qdil rewards: error: {message}"


def test_duplicate_names_are_an_error(clean_registry, tmp_path, monkeypatch) -> None:
    (tmp_path / "clash.py").write_text(PLUGIN.format(name="gail"))
    monkeypatch.setenv("QDIL_PLUGIN_PATH", str(tmp_path))
    with pytest.raises(
        ImportError, match=r"reward name 'gail' is registered twice: .*GAIL .* rename one"
    ):
        clean_registry.discover(force=True)


def test_register_refuses_non_reward_classes() -> None:
    with pytest.raises(TypeError, match="needs a RewardModel subclass"):
        registry.register_reward("thing")(dict)
    with pytest.raises(ValueError, match="lowercase identifiers"):
        registry.register_reward("Not-OK")


def test_rewards_list_command_prints_names_descriptions_and_sources(tmp_path) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "qdil.cli", "rewards", "list"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    lines = {line.split()[0]: line for line in out.strip().splitlines()}
    assert set(lines) >= BUILTINS
    assert "[qdil (built-in)]" in lines["mcwae_wgail"]
    assert "WQDIL" in lines["mcwae_wgail"]
