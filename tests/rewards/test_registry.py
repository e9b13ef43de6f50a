"""The reward registry: built-ins, entry points, local plugin folders, duplicates."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from qdil.rewards import get_reward, list_rewards, registry
from qdil.rewards.listing import ListedReward, read_listing
from tests.commands import cli

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


def _imported(clean_registry) -> list[ListedReward]:
    clean_registry.discover(force=True)
    return [ListedReward(e.name, e.description, e.source) for e in clean_registry.list_rewards()]


def _printed(entries: list[ListedReward]) -> str:
    width = max(len(entry.name) for entry in entries)
    return "".join(f"{e.name:<{width}}  {e.description}  [{e.source}]\n" for e in entries)


def test_the_listing_read_from_source_equals_the_imported_registry(
    clean_registry, tmp_path, monkeypatch, capsys
) -> None:
    """Built-ins, installed entry points and a ./plugins module, read without an import."""
    (tmp_path / "plugins").mkdir()
    (tmp_path / "plugins" / "here.py").write_text(PLUGIN.format(name="here"))
    monkeypatch.chdir(tmp_path)
    listed = read_listing()
    assert listed == _imported(clean_registry)
    assert {"here", *BUILTINS} <= {entry.name for entry in listed}
    assert cli(["rewards", "list"], capsys)[:2] == (0, _printed(listed))


INHERITING = """
from qdil.rewards.builtin import GAIL
from qdil.rewards import register_reward

@register_reward("my_gail")
class MyGAIL(GAIL):
    \"\"\"GAIL under another name.\"\"\"
"""


@pytest.mark.parametrize("kind", ["package", "inherited description", "taken name"])
def test_where_the_source_leaves_a_doubt_the_listing_imports(
    kind, clean_registry, tmp_path, monkeypatch, capsys
) -> None:
    """A plugin package, a description from another model, a name taken twice: the command
    imports and prints what the registry holds (or its error)."""
    (tmp_path / "plugins").mkdir()
    if kind == "package":
        (tmp_path / "plugins" / "pack").mkdir()
        (tmp_path / "plugins" / "pack" / "__init__.py").write_text(PLUGIN.format(name="packed"))
    elif kind == "inherited description":
        (tmp_path / "plugins" / "mine.py").write_text(INHERITING)
    else:
        (tmp_path / "plugins" / "again.py").write_text(PLUGIN.format(name="gail"))
    monkeypatch.chdir(tmp_path)
    assert read_listing() is None
    code, out, err = cli(["rewards", "list"], capsys)
    if kind == "taken name":
        assert code == 1
        assert "reward name 'gail' is registered twice" in err
        return
    clean_registry._discovered = False  # the command discovered into the fixture's registry
    assert (code, out) == (0, _printed(_imported(clean_registry)))
    if kind == "inherited description":
        assert "my_gail      GAIL (Ho & Ermon 2016)" in out
    else:
        assert f"[local plugin {tmp_path / 'plugins' / 'pack'}]" in out


def test_check_imports_the_models_and_reports_a_plugin_that_fails(
    clean_registry, tmp_path, monkeypatch, capsys
) -> None:
    """The listing reads source, so a missing dependency shows only with ``--check``."""
    (tmp_path / "plugins").mkdir()
    broken = tmp_path / "plugins" / "broken.py"
    broken.write_text("import not_installed_anywhere\n" + PLUGIN.format(name="broken"))
    monkeypatch.chdir(tmp_path)
    code, out, _ = cli(["rewards", "list"], capsys)
    assert code == 0
    assert f"broken       A local test reward.  [local plugin {broken}]" in out.splitlines()
    code, out, err = cli(["rewards", "list", "--check"], capsys)
    assert code == 1
    assert f"local reward plugin {broken} failed to import" in err
    assert "No module named 'not_installed_anywhere'" in err
