"""The docs test's switch: which ``qdil`` commands it shortens, and that a short fit parses."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.docblocks.short import ES_PAIRS, ONE_MORE, TINY, enabled, shortened

ROOT = Path(__file__).resolve().parents[2]


def test_a_new_fit_gets_the_tiny_overrides_last() -> None:
    argv = ["fit", str(ROOT / "recipes/walker_mcwae.yaml"), "--qd.iterations", "60"]
    assert shortened(argv) == [*argv, *TINY]


def test_a_pretraining_reward_pretrains_briefly() -> None:
    argv = ["fit", str(ROOT / "recipes/paper/walker_giril.yaml")]
    assert shortened(argv) == [*argv, *TINY, "--reward.pretrain_epochs", "1"]
    swapped = ["fit", str(ROOT / "recipes/walker_mcwae.yaml"), "--reward", "giril"]
    assert shortened(swapped)[-2:] == ["--reward.pretrain_epochs", "1"]


def test_a_resume_goes_one_iteration_further() -> None:
    argv = ["fit", "--resume", "runs/x", "--qd.iterations", "400"]
    assert shortened(argv) == [*argv, *ONE_MORE]


@pytest.mark.parametrize(
    "argv",
    [
        ["fit", "recipes/walker_mcwae.yaml", "--print_config"],
        ["fit", "walker_lsgail.yaml", "--reward.help", "lsgail"],
        ["fit", "--help"],
        ["eval", "runs/walker_mcwae-seed0", "--episodes", "50"],
        ["rewards", "list"],
        [],
    ],
)
def test_commands_that_train_nothing_are_unchanged(argv: list[str]) -> None:
    assert shortened(argv) == argv


@pytest.mark.parametrize(("value", "on"), [("1", True), ("yes", True), ("0", False), ("", False)])
def test_the_switch(monkeypatch, value: str, on: bool) -> None:
    monkeypatch.setenv("QDIL_DOCS_SHORT", value)
    assert enabled() is on


@pytest.mark.parametrize(
    "recipe", ["walker_mcwae.yaml", "walker_ppga.yaml", "paper/humanoid_mcwae.yaml"]
)
def test_the_short_overrides_parse_on_any_recipe(recipe: str) -> None:
    """Every key of :data:`TINY` exists in laptop and paper recipes alike."""
    from qdil.cli import parse_fit

    config, _, _ = parse_fit(shortened(["fit", str(ROOT / "recipes" / recipe)])[1:])
    assert (config.qd.iterations, config.env.num_envs, config.demos.num_episodes) == (1, 6, 1)


def test_an_estimator_gets_the_options_it_has_and_none_without_one() -> None:
    """VPPO's options do not reach ES gradients or a run without an estimator."""
    for stem, extra in (("walker_cma_maega_es", ES_PAIRS), ("walker_sep_cma_mae", [])):
        argv = ["fit", str(ROOT / f"recipes/{stem}.yaml")]
        short = shortened(argv)
        assert not any(a.startswith("--rl.init_args.") and a not in extra for a in short)
        assert short[-len(extra) :] == extra if extra else short[-2:] == TINY[-2:]
        from qdil.cli import parse_fit

        config, _, _ = parse_fit(short[1:])
        assert config.qd.iterations == 1


def test_a_sweep_runs_its_first_seed_each_trial_tiny() -> None:
    argv = ["sweep", "a.yaml", "b.yaml", "--seeds", "0", "1", "2", "--report", "out/"]
    assert shortened(argv) == ["sweep", "a.yaml", "b.yaml", "--seeds", "0", "--report", "out/",
                               *TINY]  # fmt: skip


def test_a_spec_runs_each_stage_at_its_first_seed_and_grid_point(tmp_path: Path) -> None:
    import yaml

    spec = tmp_path / "table.yaml"
    stages = [
        {"name": "expert", "recipes": ["r.yaml"], "seeds": [0], "demos": {"out": "e.npz"}},
        {"name": "imitate", "recipes": ["s.yaml"], "seeds": [0, 1], "grid": {"a.b": [1, 2]}},
    ]
    spec.write_text(yaml.safe_dump({"name": "t", "stages": stages}))
    argv = shortened(["sweep", str(spec)])
    short = yaml.safe_load(Path(argv[1]).read_text())
    assert argv[2:] == TINY and short["name"] == "t"
    assert short["stages"][0] == stages[0]  # nothing to cut
    assert short["stages"][1] == {**stages[1], "seeds": [0], "grid": {"a.b": [1]}}
    assert yaml.safe_load(spec.read_text())["stages"] == stages  # the reader's file unchanged
