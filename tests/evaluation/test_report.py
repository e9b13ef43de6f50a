"""``qdil report`` on real smoke runs through the CLI: its files, tables and records."""

from __future__ import annotations

import contextlib
import csv
import gzip
import io
import json
import pickle
import shutil
import statistics
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from scipy.stats import tukey_hsd

from qdil.evaluation.report import write_report
from qdil.evaluation.runs import collect_runs
from qdil.files import write_gzipped
from tests.commands import SMOKE, qdil_here

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
METHODS = ("AIRL-Bonus", "PPGA-trueReward")  # the pairs the tests compare


def qdil_fit(*args: str, cwd: Path) -> None:
    """``qdil fit`` of the smoke recipe in this process (a run's records do not depend on it)."""
    qdil_here(["fit", str(SMOKE), *args], cwd)


def copy_run(source: Path, target: Path, **changes: dict) -> Path:
    shutil.copytree(source, target)
    config = yaml.safe_load((target / "config.yaml").read_text())
    for section, values in changes.items():
        config[section] = {**(config.get(section) or {}), **values}
    (target / "config.yaml").write_text(yaml.safe_dump(config))
    return target


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as file:
        return list(csv.DictReader(file))


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> SimpleNamespace:
    """Three true-reward smoke runs, faked copies as other methods, a broken and a lost run."""
    from qdil.cli import main
    from qdil.evaluation.rescore import rescore_archive

    root = tmp_path_factory.mktemp("report")
    for seed in range(3):
        qdil_fit("--name", f"true{seed}", "--seed", str(seed), cwd=root)
    runs = root / "runs"
    airl = {"class_path": "not.installed.AIRL"}
    for seed in range(3):  # the same archives, relabelled; two of them re-scored
        copy_run(runs / f"true{seed}", runs / f"airl{seed}", reward=airl, bonus={"enabled": True})
    for seed in range(2):
        rescore_archive(runs / f"airl{seed}", episodes=1, num_threads=1)
    copy_run(
        runs / "true0", runs / "giril0", reward={"class_path": "x.GIRIL"}, qd={"iterations": 10}
    )
    (runs / "broken").mkdir()
    shutil.copy(runs / "true0" / "config.yaml", runs / "broken" / "config.yaml")
    out = root / "report"
    stdout = io.StringIO()
    ghost = root / "ghost"
    args = ["report", str(runs), str(root / "lost"), "--out", str(out), "--label", f"{ghost}=G"]
    args += ["--videos", "0"]  # tests/evaluation/test_report_page.py makes videos
    with contextlib.redirect_stdout(stdout):
        main(args)
    return SimpleNamespace(root=root, runs=runs, out=out, stdout=stdout.getvalue())


def test_every_file_exists_and_pngs_are_not_empty(made: SimpleNamespace) -> None:
    out = made.out
    for name in ("report.md", "report.html", "table.md", "table.csv", "tukey.md", "tukey.csv"):
        assert (out / name).stat().st_size > 0, name
    heatmaps = sorted((out / "heatmaps").glob("*.png"))
    curves = sorted((out / "curves").glob("*.png"))
    assert len(heatmaps) == 7  # 3 true reward + 3 AIRL-Bonus + 1 unfinished GIRIL
    assert [p.name for p in curves] == [
        f"Walker2d-v5__{m}.png" for m in ("coverage", "obj_max", "obj_mean", "qd_score")
    ]
    for png in heatmaps + curves:
        data = png.read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 5000, png
    report = (out / "report.md").read_text()
    for png in heatmaps + curves:
        assert f"]({png.relative_to(out)})" in report  # linked with a relative path
    assert "| Method | Walker2d n | Walker2d QD-Score | Walker2d Cov(%)" in report
    assert "<table>" in (out / "report.html").read_text()
    assert str(out / "report.md") in made.stdout and "| PPGA-trueReward | 3 |" in made.stdout


def test_labels_and_sources(made: SimpleNamespace) -> None:
    runs = {Path(r["path"]).name: r for r in read_csv(made.out / "runs.csv")}
    assert {name: r["method"] for name, r in runs.items() if r["method"]} == {
        "true0": "PPGA-trueReward",
        "true1": "PPGA-trueReward",
        "true2": "PPGA-trueReward",
        "airl0": "AIRL-Bonus",
        "airl1": "AIRL-Bonus",
        "airl2": "AIRL-Bonus",
        "giril0": "GIRIL",
        "broken": "PPGA-trueReward",
    }
    for name in ("airl0", "airl1"):
        assert runs[name]["source"].startswith("corrected (qdil eval")
        corrected = json.loads((made.runs / name / "eval.json").read_text())["metrics"]
        assert float(runs[name]["qd_score"]) == pytest.approx(corrected["qd_score"])
        assert float(runs[name]["coverage_pct"]) == pytest.approx(100 * corrected["coverage"])
    for name in ("airl2", "true0", "true1", "true2"):
        assert runs[name]["source"].startswith("training archive")
    assert runs["airl2"]["qd_score"] == runs["true2"]["qd_score"]  # same archive, relabelled
    sources = (made.out / "report.md").read_text()
    assert "Walker2d-v5 / AIRL-Bonus: 2 of 3 run(s) from corrected archives" in sources


def test_unfinished_and_missing_runs_are_reported(made: SimpleNamespace) -> None:
    runs = {Path(r["path"]).name: r for r in read_csv(made.out / "runs.csv")}
    assert runs["giril0"]["status"] == "included, unfinished"
    assert "unfinished: 3 iterations logged" in runs["giril0"]["reason"]
    assert runs["broken"]["status"] == "left out"
    assert "no metrics.csv" in runs["broken"]["reason"]
    assert "no readable checkpoint" in runs["broken"]["reason"]
    assert runs["lost"]["status"] == "left out" and "does not exist" in runs["lost"]["reason"]
    assert runs["ghost"]["status"] == "left out" and "--label" in runs["ghost"]["reason"]
    report = (made.out / "report.md").read_text()
    section = report.split("## Runs left out / unfinished")[1]
    for name in ("giril0", "broken", "lost", "ghost"):
        assert name in section
    table = (made.out / "table.md").read_text()
    assert "| GIRIL | 1* |" in table and "(n=1)" in table
    assert "broken: left out" in made.stdout and "giril0: included, unfinished" in made.stdout


def test_table_csv_is_mean_and_sample_std_of_the_runs(made: SimpleNamespace) -> None:
    runs = read_csv(made.out / "runs.csv")
    table = read_csv(made.out / "table.csv")
    assert {(r["task"], r["method"]) for r in table} == {
        ("Walker2d-v5", "PPGA-trueReward"),
        ("Walker2d-v5", "AIRL-Bonus"),
        ("Walker2d-v5", "GIRIL"),
    }
    for row in table:
        mine = [r for r in runs if r["method"] == row["method"] and r["status"] != "left out"]
        assert int(row["n"]) == len(mine)
        for key in ("qd_score", "qd_score_offset", "coverage_pct", "obj_max", "obj_mean"):
            values = [float(r[key]) for r in mine]
            assert float(row[f"{key}_mean"]) == pytest.approx(statistics.mean(values))
            std = statistics.stdev(values) if len(values) > 1 else 0.0
            assert float(row[f"{key}_std"]) == pytest.approx(std, abs=1e-12)


def test_profile_csv_counts_the_final_archives_elites(made: SimpleNamespace) -> None:
    runs = [r for r in collect_runs([made.runs]) if r.included]
    rows = read_csv(made.out / "profile.csv")
    assert {r["method"] for r in rows} == {"PPGA-trueReward", "AIRL-Bonus", "GIRIL"}
    assert len({r["return_at_least"] for r in rows}) == 3
    for row in rows:
        level = float(row["return_at_least"])
        shares = [
            100 * np.count_nonzero(r.archive.data("objective") >= level) / r.archive.cells
            for r in runs
            if r.method == row["method"]
        ]
        assert int(row["n"]) == len(shares)
        assert float(row["cells_pct_mean"]) == pytest.approx(statistics.mean(shares))
    png = made.out / "profiles" / "Walker2d-v5.png"
    assert png.read_bytes().startswith(PNG_MAGIC)
    report = (made.out / "report.md").read_text()
    assert "## Return profiles of the final archives" in report
    assert "](profiles/Walker2d-v5.png)" in report and "| Method | n | cells ≥ " in report


def test_tukey_csv_equals_scipy_on_the_run_values(made: SimpleNamespace) -> None:
    runs = [r for r in read_csv(made.out / "runs.csv") if r["status"] != "left out"]
    rows = read_csv(made.out / "tukey.csv")  # GIRIL has one seed: left out
    for score, column in (("raw", "qd_score"), ("offset", "qd_score_offset")):
        airl, expert = (
            np.array([float(r[column]) for r in runs if r["method"] == m]) for m in METHODS
        )
        (row,) = [r for r in rows if r["qd_score"] == score]
        assert (row["group1"], row["group2"]) == METHODS
        assert float(row["pvalue"]) == pytest.approx(tukey_hsd(airl, expert).pvalue[0, 1], rel=1e-9)
        assert float(row["diff"]) == pytest.approx(expert.mean() - airl.mean())
        assert row["sign"] == ("+" if expert.mean() > airl.mean() else "-")
    tukey_md = (made.out / "tukey.md").read_text()
    assert "| AIRL-Bonus | PPGA-trueReward |" in tukey_md and "Offset QD-Score" in tukey_md
    assert "GIRIL left out of the Tukey HSD test: 1 seed(s)" in tukey_md


def test_label_override(made: SimpleNamespace) -> None:
    runs = collect_runs([made.runs / "true2"], labels={str(made.runs / "true2"): "Custom"})
    assert [(r.method, r.status) for r in runs] == [("Custom", "included")]
    assert runs[0].archive is not None and len(runs[0].archive) > 0


def test_records_remake_the_same_report_without_checkpoints(
    made: SimpleNamespace, tmp_path: Path
) -> None:
    kept = made.out / "runs"
    # every included run is kept, none of the left-out ones, and no policy goes with them
    assert sorted(p.name for p in kept.iterdir()) == sorted(
        ["true0", "true1", "true2", "airl0", "airl1", "airl2", "giril0"]
    )
    assert not list(kept.rglob("*.pt")) and not list(kept.rglob("*.pkl"))
    assert (kept / "airl0" / "eval.json").is_file() and not (kept / "true0" / "eval.json").exists()
    # both tables are kept gzipped (records travel with the repository), the metrics byte
    # for byte the run's, the same bytes each time they are written
    assert not (kept / "airl0" / "metrics.csv").exists()
    metrics = (kept / "airl0" / "metrics.csv.gz").read_bytes()
    assert gzip.decompress(metrics) == (made.runs / "airl0" / "metrics.csv").read_bytes()
    write_gzipped(tmp_path / "again.gz", gzip.decompress(metrics))
    assert (tmp_path / "again.gz").read_bytes() == metrics
    assert gzip.decompress((kept / "airl0" / "archive.csv.gz").read_bytes()).startswith(b"index,")
    # the records alone, moved elsewhere, give the same tables
    moved = shutil.copytree(kept, tmp_path / "records")
    again = write_report([moved], tmp_path / "again")
    before, after = read_csv(made.out / "runs.csv"), read_csv(tmp_path / "again" / "runs.csv")
    before = {Path(r["path"]).name: r for r in before if r["status"] != "left out"}
    after = {Path(r["path"]).name: r for r in after}
    assert before.keys() == after.keys()
    for name, row in after.items():
        assert row["status"] == before[name]["status"] and row["iteration"]
        for key in ("qd_score", "qd_score_offset", "coverage_pct", "obj_max", "obj_mean"):
            assert float(row[key]) == float(before[name][key]), (name, key)
        assert row["source"].startswith(before[name]["source"])
        assert "from the record of" in row["source"]
    assert (tmp_path / "again" / "table.csv").read_text() == (made.out / "table.csv").read_text()
    again_deployable = (tmp_path / "again" / "table_deployable.csv").read_text()
    assert again_deployable == (made.out / "table_deployable.csv").read_text()
    assert (tmp_path / "again" / "tukey.csv").read_text() == (made.out / "tukey.csv").read_text()
    # the corrected archive of a re-scored run is the one kept, cell for cell
    (airl0,) = [r for r in again.runs if r.path.name == "airl0"]
    with open(made.runs / "airl0" / "corrected_archive.pkl", "rb") as file:
        corrected = pickle.load(file)
    expected = corrected.data(["index", "objective"])
    got = airl0.archive.data(["index", "objective"])
    order, order_got = np.argsort(expected["index"]), np.argsort(got["index"])
    assert np.array_equal(expected["index"][order], got["index"][order_got])
    assert np.array_equal(expected["objective"][order], got["objective"][order_got])
    # records of records are copied as they are
    assert (tmp_path / "again" / "runs" / "true0" / "record.json").read_text() == (
        kept / "true0" / "record.json"
    ).read_text()


def test_the_deployable_archives_are_tabled_beside_the_true_keyed_ones(
    made: SimpleNamespace,
) -> None:
    """True-reward runs choose their elites by the true return: their two archives agree
    (up to the order in which pyribs sums the same elites)."""
    true_rows, deployable_rows = (
        read_csv(made.out / n) for n in ("table.csv", "table_deployable.csv")
    )
    assert len(true_rows) == len(deployable_rows) == 3
    for a, b in zip(true_rows, deployable_rows, strict=True):
        assert a.keys() == b.keys()
        for key in a:
            if key.endswith(("_mean", "_std")):
                assert float(b[key]) == pytest.approx(float(a[key]), rel=1e-12, nan_ok=True)
            else:
                assert b[key] == a[key], key
    page = (made.out / "report.md").read_text()
    assert "the true-keyed archives (the paper's protocol)" in page
    assert "The deployable archives" in page and "oracle" in page
    rows = {Path(r["path"]).name: r for r in read_csv(made.out / "runs.csv")}
    deployable, true = (float(rows["airl0"][k]) for k in ("deployable_qd_score", "qd_score"))
    assert deployable == pytest.approx(true, rel=1e-12)
    assert rows["airl0"]["deployable_source"].startswith("corrected")
    assert rows["true2"]["deployable_source"].startswith("training archive")


def test_ratios_to_the_expert_are_ratios_of_the_runs_means(made: SimpleNamespace) -> None:
    runs = [r for r in read_csv(made.out / "runs.csv") if r["status"].startswith("included")]
    ratios = read_csv(made.out / "ratios.csv")
    assert len({(r["archive"], r["qd_score"]) for r in ratios}) == 4  # both archives, both scores
    by_name = {(r["archive"], r["qd_score"], r["ratio"]): r for r in ratios}
    columns = {"qd_score": ("true", "raw"), "deployable_qd_score": ("deployable", "raw")}
    for column, (archive, score) in {**columns, "qd_score_offset": ("true", "offset")}.items():
        airl, expert = ([float(r[column]) for r in runs if r["method"] == m] for m in METHODS)
        row = by_name[(archive, score, "AIRL-Bonus / PPGA-trueReward")]
        assert float(row["value"]) == pytest.approx(np.mean(airl) / np.mean(expert))
        assert float(row["low"]) <= float(row["value"]) <= float(row["high"]) and row["n"] == "3/3"
        # bounded where the expert's seeds share a sign (with 3 seeds the bootstrap's 2.5 %
        # quantile of their mean is the lowest seed: 1/27 of resamples repeat it thrice)
        assert row["bounded"] == str(min(expert) > 0 or max(expert) < 0)
    assert by_name[("true", "offset", "AIRL-Bonus / PPGA-trueReward")]["bounded"] == "True"
    single = by_name[("true", "raw", "GIRIL / PPGA-trueReward")]
    assert single["n"] == "1/3" and single["low"] == "nan" and single["seeds_to_resolve"] == ""
    assert "Ratios to the expert and to GAIL" in (made.out / "report.md").read_text()


def test_eval_json_and_records_say_which_code_and_settings_made_them(
    made: SimpleNamespace,
) -> None:
    from qdil.provenance import git_state

    commit, dirty = git_state()
    evaluation = json.loads((made.runs / "airl0" / "eval.json").read_text())
    assert evaluation["reset_seed"] == 0 and evaluation["episodes_per_elite"] == 1
    made_by = evaluation["provenance"]
    assert (made_by["commit"], made_by["dirty"]) == (commit, dirty)
    assert {"qdil", "torch", "mujoco", "ribs"} <= {k for k, v in made_by["versions"].items() if v}
    assert made_by["numerics"].get("MKL_CBWR", "STRICT").endswith("STRICT")
    trained = json.loads((made.runs / "true0" / "provenance.json").read_text())
    assert [start["from_iteration"] for start in trained] == [0]
    assert trained[0]["commit"] == commit
    # both policy archives are re-scored; a true-reward run's two archives are one
    deployable = evaluation["deployable"]
    for key in ("metrics", "training_metrics"):  # the same elites, summed in another order
        assert deployable[key] == pytest.approx(evaluation[key], rel=1e-12, nan_ok=True)
    assert evaluation["qd_score_se"] >= 0.0 and deployable["qd_score_se"] >= 0.0
    assert (made.runs / "airl0" / "corrected_deployable.pkl").is_file()
    record = json.loads((made.out / "runs" / "airl0" / "record.json").read_text())["provenance"]
    assert record["evaluation"]["reset_seed"] == 0 and record["evaluation"]["provenance"]
    assert record["training"] == trained and record["report"]["commit"] == commit
    assert (made.out / "runs" / "true0" / "provenance.json").is_file()


def test_records_keep_the_method_labels_of_their_report(
    made: SimpleNamespace, tmp_path: Path
) -> None:
    kept = shutil.copytree(made.out / "runs", tmp_path / "records")
    labelled = write_report([kept], tmp_path / "labelled", labels={kept / "true0": "Expert A"})
    assert {r.path.name: r.method for r in labelled.runs}["true0"] == "Expert A"
    # remade from the labelled report's records, with no --label: the runs group as before
    again = write_report([tmp_path / "labelled" / "runs"], tmp_path / "again")
    methods = {r.path.name: r.method for r in again.runs}
    assert methods["true0"] == "Expert A"
    assert methods["true1"] == {r.path.name: r.method for r in labelled.runs}["true1"]
    # a label given now still wins over the one a record kept
    relabelled = write_report(
        [tmp_path / "labelled" / "runs"],
        tmp_path / "relabelled",
        labels={tmp_path / "labelled" / "runs" / "true0": "Expert B"},
    )
    assert {r.path.name: r.method for r in relabelled.runs}["true0"] == "Expert B"
    record = json.loads((tmp_path / "relabelled" / "runs" / "true0" / "record.json").read_text())
    assert record["method"] == "Expert B"


def test_an_unreadable_record_is_left_out_with_its_reason(
    made: SimpleNamespace, tmp_path: Path
) -> None:
    record = shutil.copytree(made.out / "runs" / "true0", tmp_path / "true0")
    (record / "archive.csv.gz").unlink()
    (run,) = collect_runs([record])
    assert run.status == "left out" and "record unreadable" in run.problems[0]


def test_eval_and_report_read_each_checkpoint_once(
    made: SimpleNamespace, tmp_path: Path, monkeypatch
) -> None:
    # a paper-scale checkpoint is hundreds of MB: both archives come from one read
    from qdil.evaluation import runs as runs_module
    from qdil.evaluation.rescore import rescore_archive
    from qdil.qd import checkpoint

    reads: list[Path] = []
    original = checkpoint.read_checkpoint

    def counted(path: Path) -> dict:
        reads.append(path)
        return original(path)

    monkeypatch.setattr(checkpoint, "read_checkpoint", counted)
    run = shutil.copytree(made.runs / "true2", tmp_path / "true2")
    rescore_archive(run, episodes=1, num_threads=1)
    assert len(reads) == 1
    reads.clear()
    runs_module.load_run(run)
    assert len(reads) == 1


def test_runs_of_one_label_and_another_configuration_are_not_pooled(
    made: SimpleNamespace, tmp_path: Path
) -> None:
    runs = made.runs
    wider = copy_run(runs / "true0", tmp_path / "wider0", qd={"cells": 20})  # same seed, label
    report = write_report([runs / f"true{seed}" for seed in range(3)] + [wider], tmp_path / "out")
    rows = {method: len(group) for method, group in report.groups["Walker2d-v5"].items()}
    assert rows == {"PPGA-trueReward [qd.cells=10]": 3, "PPGA-trueReward [qd.cells=20]": 1}
    (run,) = [r for r in report.runs if r.path == wider]
    assert "differs in qd.cells" in run.notes[-1]
    assert not any("also used by" in note for r in report.runs for note in r.notes)
