"""Sweep specs: stages of recipes × seeds × grids, checked before anything starts, run in
order (an expert, its demonstrations, then the imitation runs that read them), each trial
equal to the plain ``qdil fit`` of its options."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("ray.tune")

import ray
import yaml

from qdil.cli import main
from qdil.sweeps.spec import load_spec, text
from tests.cli.test_reproducible_runs import archives, metrics, same_archives

ROOT = Path(__file__).resolve().parents[2]
SMOKE = str(ROOT / "recipes" / "smoke" / "walker_true.yaml")
IL = str(ROOT / "recipes" / "smoke" / "walker_il.yaml")
TABLE = {
    "name": "smoke-table",
    "episodes": 1,
    "overrides": {"qd.iterations": 2},
    "stages": [
        {
            "name": "expert",
            "recipes": [SMOKE],
            "seeds": [0],
            "cpus_per_trial": 2,
            "demos": {"out": "expert.npz", "top": 5, "num": 2},
        },
        {
            "name": "imitate",
            "recipes": [{"recipe": IL, "overrides": {"bonus.enabled": False}}],
            "seeds": [1],
            "grid": {"rl.init_args.learning_rate": [0.001, 0.003]},
            "overrides": {"demos.path": "expert.npz"},
            "report": "report",
        },
    ],
}


@pytest.fixture(scope="module", autouse=True)
def _ray_down():
    yield
    if ray.is_initialized():
        ray.shutdown()


@pytest.fixture
def one_ray() -> None:
    """A local Ray for the in-process sweeps (2 CPUs), started once: each run of the spec
    joins it instead of starting its own."""
    if not ray.is_initialized():
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)


def write(folder: Path, spec: dict) -> Path:
    path = folder / "spec.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


@pytest.mark.parametrize(
    ("value", "said"), [("a", "a"), (True, "true"), (0.0001, "0.0001"), ([64, 64], "[64, 64]")]
)
def test_spec_values_are_written_as_a_command_line_writes_them(value, said) -> None:
    assert text(value) == said


def test_a_spec_plans_every_recipe_grid_point_and_seed_in_order(tmp_path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    spec = load_spec(write(tmp_path, TABLE), [("logging.heatmap_every", "0")])
    expert, imitate = spec.stages
    assert [t.name for t in expert.trials] == ["walker_true-seed0"]  # iterations: no hash
    assert expert.cpus == 2 and expert.demos["out"] == "expert.npz"
    assert len(imitate.trials) == 2 and imitate.report == Path("report")
    first = imitate.trials[0]
    assert first.overrides == (
        ("qd.iterations", "2"),
        ("demos.path", "expert.npz"),  # made by the stage before: not refused
        ("bonus.enabled", "false"),
        ("rl.init_args.learning_rate", "0.001"),
        ("logging.heatmap_every", "0"),  # the command line's, last
    )
    assert len({t.name for t in imitate.trials}) == 2


@pytest.mark.parametrize(
    ("change", "said"),
    [
        (lambda s: s.update(seed=[0]), "unknown key 'seed'"),
        (lambda s: s["stages"][1].pop("seeds"), r"stages\[1\]: seeds"),
        (lambda s: s["stages"][1].update(name="expert"), "'expert' is used twice"),
        (lambda s: s["stages"][1].update(grid={"qd.cells": 5}), "grid: give a mapping"),
        (lambda s: s["stages"][0].pop("demos"), r"expert\.npz: no such file"),
        (lambda s: s["stages"][0]["demos"].pop("out"), "demos: give out"),
        (lambda s: s["stages"][1].update(overrides={"qd.cels": 5}), "cels"),
    ],
)
def test_a_bad_spec_is_refused_naming_the_file_and_key(tmp_path, monkeypatch, change, said):
    monkeypatch.chdir(tmp_path)
    spec = yaml.safe_load(yaml.safe_dump(TABLE))
    change(spec)
    with pytest.raises(SystemExit, match=said):
        main(["sweep", str(write(tmp_path, spec))])
    assert not (tmp_path / "runs").exists()


def test_a_spec_runs_its_stages_in_order_each_trial_a_plain_fit(one_ray, tmp_path, monkeypatch):
    """One grid point runs (planning every point is the test above): the trial that
    matters, with the learning rate a plain fit is given below."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("QDIL_PLUGIN_PATH", raising=False)
    table = yaml.safe_load(yaml.safe_dump(TABLE))
    table["stages"][1]["grid"] = {"rl.init_args.learning_rate": [0.003]}
    path = write(tmp_path, table)
    main(["sweep", str(path)])
    assert (tmp_path / "expert.npz").is_file()  # the expert's demonstrations, then imitation
    assert (tmp_path / "report" / "report.md").is_file()
    runs = sorted((tmp_path / "runs").glob("walker_il-*-seed1"))
    assert len(runs) == 1 and all((run / "eval.json").is_file() for run in runs)
    main(["fit", IL, "--seed", "1", "--qd.iterations", "2", "--demos.path", "expert.npz",
          "--bonus.enabled", "false", "--rl.init_args.learning_rate", "0.003",
          "--logging.root", "plain"])  # fmt: skip
    plain = tmp_path / "plain" / "walker_il-seed1"
    (trial,) = [run for run in runs if metrics(run) == metrics(plain)]
    assert same_archives(archives(trial), archives(plain))
    # the same command again: every stage is finished, nothing is written
    before = {p: p.stat().st_mtime_ns for p in (tmp_path / "runs").glob("walker_*/**/*")}
    main(["sweep", str(path)])
    assert before == {p: p.stat().st_mtime_ns for p in (tmp_path / "runs").glob("walker_*/**/*")}


@pytest.mark.parametrize("spec", sorted((ROOT / "sweeps").glob("*.yaml")), ids=lambda p: p.name)
def test_every_shipped_spec_plans_and_checks(spec: Path, monkeypatch) -> None:
    """The specs behind the evidence and the paper's table stay runnable as written."""
    monkeypatch.chdir(ROOT)  # their paths are the repository's
    stages = load_spec(spec, [], root=Path("/nonexistent/runs")).stages
    assert stages and all(stage.trials for stage in stages)


def test_stages_named_alone_need_what_the_stages_left_out_would_make(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = write(tmp_path, TABLE)
    (expert,) = load_spec(path, [], only=["expert"]).stages
    assert expert.name == "expert"
    with pytest.raises(SystemExit, match=r"expert\.npz: no such file"):
        load_spec(path, [], only=["imitate"])
    with pytest.raises(SystemExit, match="no stage 'imitation'"):
        main(["sweep", str(path), "--stages", "imitation"])
