"""``qdil report``'s parts on hand-made numbers: statistics, tables, labels, profiles, runs."""

from __future__ import annotations

import json
import statistics
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from ribs.archives import GridArchive
from scipy.stats import tukey_hsd

from qdil.evaluation import document as doc
from qdil.evaluation.configurations import flag_duplicate_seeds
from qdil.evaluation.methods import method_label
from qdil.evaluation.profiles import archive_profile, method_profile, profile_levels
from qdil.evaluation.report import (
    colour_range,
    format_pvalue,
    keep_records,
    main_table,
    tukey_tests,
)
from qdil.evaluation.runs import RunResult, find_runs, group_runs
from qdil.evaluation.stats import Summary, align_curves, format_mean_std, summarize, tukey
from qdil.evaluation.tables import ratio_records, ratio_table, run_records, table_records


def test_summarize_uses_the_sample_std() -> None:
    values = [1.0, 2.0, 3.0, 4.0]
    summary = summarize(values)
    assert summary.mean == pytest.approx(2.5)
    assert summary.std == pytest.approx(statistics.stdev(values))  # ddof=1: 1.2910
    assert summary.std != pytest.approx(statistics.pstdev(values))  # not ddof=0: 1.1180
    assert summary.n == 4


def test_single_seed_says_so() -> None:
    summary = summarize([3.8e6])
    assert summary == Summary(3.8e6, 0.0, 1)
    assert format_mean_std(summary, "sci") == "3.80e+06 (n=1)"
    assert format_mean_std(summarize([]), "sci") == "–"


@pytest.mark.parametrize(
    ("summary", "style", "text"),
    [
        (Summary(3.8e6, 2.85e5, 5), "sci", "3.80e+06 ± 2.85e+05"),
        (Summary(98.284, 0.4166, 3), "fixed", "98.28 ± 0.42"),
        (Summary(4553.2, 547.4, 3), "int", "4,553 ± 547"),
        (Summary(float("nan"), float("nan"), 2), "int", "nan ± nan"),
    ],
)
def test_mean_std_formatting(summary: Summary, style: str, text: str) -> None:
    assert format_mean_std(summary, style) == text


GROUPS = {
    "mCWAE-WGAIL-Bonus": [3.1, 3.0, 3.2, 2.9, 3.05],
    "GAIL": [2.0, 2.6, 2.2, 2.4, 1.9],
    "AIRL": [2.9, 3.3, 2.5, 2.7, 3.1],
}


def test_tukey_pvalues_equal_scipy_on_the_same_arrays() -> None:
    result = tukey(GROUPS)
    names = sorted(GROUPS)  # AIRL, GAIL, mCWAE-WGAIL-Bonus
    expected = tukey_hsd(*[np.array(GROUPS[name]) for name in names]).pvalue
    assert len(result.comparisons) == 3 and not result.notes
    for c in result.comparisons:
        i, j = names.index(c.group1), names.index(c.group2)
        assert i < j
        assert c.pvalue == pytest.approx(expected[i, j], rel=1e-12)
        assert c.diff == pytest.approx(np.mean(GROUPS[c.group2]) - np.mean(GROUPS[c.group1]))
        assert c.sign == ("+" if c.diff > 0 else "-")
    gail = next(
        c for c in result.comparisons if c.group2 == "mCWAE-WGAIL-Bonus" and c.group1 == "GAIL"
    )
    assert gail.sign == "+" and gail.significant and gail.pvalue < 0.001


def test_tukey_leaves_out_single_seeds_and_skips_with_one_method() -> None:
    result = tukey({**GROUPS, "PWIL": [2.0]})
    assert {c.group1 for c in result.comparisons} | {c.group2 for c in result.comparisons} == set(
        GROUPS
    )
    assert any("PWIL" in note and "1 seed" in note for note in result.notes)
    skipped = tukey({"GAIL": [1.0, 2.0], "PWIL": [2.0]})
    assert skipped.comparisons == []
    assert any("skipped" in note for note in skipped.notes)


def fake_run(task: str, method: str, qd_score: float, seed: int = 0) -> RunResult:
    return RunResult(
        path=Path(f"{method}-{seed}"),
        task=task,
        method=method,
        seed=seed,
        metrics={
            "qd_score": qd_score,
            "qd_score_offset": qd_score + 10,
            "coverage": 0.5,
            "obj_max": 100.0,
            "obj_mean": 50.0,
        },
    )


def test_reference_orients_pairs_as_group2() -> None:
    runs = [fake_run("T", m, v, s) for m, vs in GROUPS.items() for s, v in enumerate(vs)]
    plain = tukey_tests(group_runs(runs))["T"].comparisons
    oriented = tukey_tests(group_runs(runs), reference="AIRL")["T"].comparisons
    assert len(oriented) == 2 and all(c.group2 == "AIRL" for c in oriented)
    for c in oriented:
        twin = next(p for p in plain if {p.group1, p.group2} == {c.group1, c.group2})
        assert c.pvalue == twin.pvalue and c.diff == pytest.approx(-twin.diff)
        assert c.diff == pytest.approx(np.mean(GROUPS["AIRL"]) - np.mean(GROUPS[c.group1]))


def test_main_table_rows_and_single_seed_cells() -> None:
    runs = [fake_run("Walker2d-v5", "GAIL", 1e6, 0), fake_run("Walker2d-v5", "GAIL", 3e6, 1)]
    runs += [fake_run("Walker2d-v5", "PPGA-trueReward", 5e6), fake_run("Hopper-v5", "GAIL", 2e6)]
    header, rows = main_table(group_runs(runs))
    assert header[:3] == ["Method", "Walker2d n", "Walker2d QD-Score"]
    assert header[6:8] == ["Hopper n", "Hopper QD-Score"]
    assert [row[0] for row in rows] == ["PPGA-trueReward", "GAIL"]  # true reward first
    gail = rows[1]
    assert gail[1] == "2" and gail[2] == f"2.00e+06 ± {statistics.stdev([1e6, 3e6]):.2e}"
    assert gail[3] == "50.00 ± 0.00"
    assert gail[7] == "2.00e+06 (n=1)"
    assert rows[0][6] == "–"  # no true-reward run on Hopper


def test_another_integrator_is_another_task_column() -> None:
    runs = [fake_run("Walker2d-v5", "GAIL", 1e6, s) for s in range(2)]
    euler = [fake_run("Walker2d-v5", "GAIL", 4e6, s) for s in range(2)]
    for run in euler:
        run.integrator = "euler"
    runs += [*euler, fake_run("HalfCheetah-v5", "GAIL", 2e6)]
    groups = group_runs(runs)
    # the paper's order, the changed integrator beside its task; never pooled with v5 runs
    assert list(groups) == ["HalfCheetah-v5", "Walker2d-v5", "Walker2d-v5 (euler)"]
    assert groups["Walker2d-v5 (euler)"]["GAIL"] == euler
    header = main_table(groups)[0]
    assert "Walker2d (euler) QD-Score" in header and "Walker2d QD-Score" in header
    assert run_records(euler)[0]["task"] == "Walker2d-v5 (euler)"


def test_deployable_tables_and_ratios_use_the_runs_that_have_that_archive() -> None:
    # seeds 0-1 predate the deployable archive (older checkpoints), seeds 2-3 have it
    runs = [
        fake_run("Walker2d-v5", m, 1e6 * (s + 1), s) for m in ("GAIL", "WQDIL") for s in range(4)
    ]
    for run in runs[2:4] + runs[6:8]:
        run.deployable = {**run.metrics, "qd_score": run.metrics["qd_score"] / 2}
    groups = group_runs(runs)
    _, rows = main_table(groups, "deployable")
    wqdil = next(row for row in rows if row[0] == "WQDIL")
    assert wqdil[1] == "2" and wqdil[2] == f"1.75e+06 ± {statistics.stdev([1.5e6, 2e6]):.2e}"
    record = next(r for r in table_records(groups, "deployable") if r["method"] == "WQDIL")
    assert (record["n"], record["seeds"], record["qd_score_mean"]) == (2, "2 3", 1.75e6)
    assert next(r for r in table_records(groups) if r["method"] == "WQDIL")["n"] == 4
    ratios = {(r["archive"], r["qd_score"]): r for r in ratio_records(groups)}
    assert ratios["deployable", "raw"]["value"] == pytest.approx(1.0)
    assert ratios["deployable", "raw"]["n"] == "2/2" and ratios["true", "raw"]["n"] == "4/4"


def test_a_ratio_of_one_seed_a_side_is_shown_without_an_interval() -> None:
    groups = group_runs(
        [fake_run("Humanoid-v5", m, v, 0) for m, v in (("GAIL", 2e5), ("WQDIL", 3e5))]
    )
    records = [
        r for r in ratio_records(groups) if r["archive"] == "true" and r["qd_score"] == "raw"
    ]
    _, rows = ratio_table(records)
    assert [row[4] for row in rows] == ["1.50, no interval: one seed"]
    assert rows[0][5] == "1/1" and rows[0][6] == "–"


def test_records_carry_the_provenance_the_report_took_before_writing(tmp_path: Path) -> None:
    # a report rewriting its own tracked folder must not call its tree dirty
    run_dir = tmp_path / "gail-seed0"
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text("seed: 0\n")
    archive = GridArchive(solution_dim=1, dims=[2, 2], ranges=[(0, 1), (0, 1)])
    archive.add([[0.0]], [5.0], [[0.2, 0.7]])
    run = fake_run("Humanoid-v5", "GAIL", 5.0)
    run.path, run.archive, run.iteration = run_dir, archive, 100
    made_by = {"commit": "e168ef1", "dirty": False}
    assert keep_records([run], tmp_path / "out" / "runs", made_by) == ["runs/gail-seed0"]
    record = json.loads((tmp_path / "out" / "runs" / "gail-seed0" / "record.json").read_text())
    assert record["provenance"]["report"] == made_by
    assert (tmp_path / "out" / "runs" / "gail-seed0" / "config.yaml").read_text() == "seed: 0\n"


def test_duplicate_seeds_are_flagged() -> None:
    runs = [
        fake_run("T", "GAIL", 1.0, 0),
        fake_run("T", "GAIL", 2.0, 1),
        fake_run("T", "AIRL", 1, 0),
    ]
    runs[1].seed = 0
    flag_duplicate_seeds(group_runs(runs))
    assert "seed 0 also used by GAIL-1" in runs[0].notes[0]
    assert "seed 0 also used by GAIL-0" in runs[1].notes[0]
    assert runs[2].notes == []


def test_align_curves_keeps_the_iterations_every_seed_has() -> None:
    long = (np.array([1, 2, 3, 4, 5]), np.array([1.0, 2.0, 3.0, 4.0, 5.0]))
    short = (np.array([1, 2, 3]), np.array([3.0, 2.0, 7.0]))
    steps, mean, std = align_curves([long, short])
    np.testing.assert_array_equal(steps, [1, 2, 3])
    np.testing.assert_allclose(mean, [2.0, 2.0, 5.0])
    np.testing.assert_allclose(std, [statistics.stdev([1, 3]), 0.0, statistics.stdev([3, 7])])
    steps, mean, std = align_curves([short])
    np.testing.assert_array_equal(std, [0.0, 0.0, 0.0])


def test_pvalue_bold_at_and_below_alpha() -> None:
    assert format_pvalue(0.05) == "**0.0500**"
    assert format_pvalue(0.0501) == "0.0501"
    assert format_pvalue(1e-7) == "**<0.0001**"


@pytest.mark.parametrize(
    ("config", "label"),
    [
        ({"reward": {"class_path": "qdil.rewards.builtin.TrueReward"}}, "PPGA-trueReward"),
        (
            {"reward": {"class_path": "not.installed.AIRL"}, "bonus": {"enabled": True}},
            "AIRL-Bonus",
        ),
        (
            {"reward": {"class_path": "plug.mcwae_wgail"}, "bonus": {"enabled": False}},
            "mCWAE-WGAIL",
        ),
        ({"reward": {"class_path": "plug.MyReward"}, "bonus": {"enabled": True}}, "MyReward-Bonus"),
        ({"reward": "gail"}, "GAIL"),
        ({"reward": "gail", "bonus": {"enabled": True, "type": "ebc"}}, "GAIL-EBC"),
        ({"reward": "diffail", "bonus": {"enabled": True, "type": "single_step"}}, "DiffAIL-Bonus"),
    ],
)
def test_method_labels(config: dict, label: str) -> None:
    assert method_label(config) == label


def test_colour_range_spans_every_archive() -> None:
    archives = []
    for objectives in ([1.0, -4.0], [9.0]):
        archive = GridArchive(solution_dim=1, dims=[4, 4], ranges=[(0, 1), (0, 1)])
        measures = np.linspace(0.1, 0.9, 2 * len(objectives)).reshape(-1, 2)
        archive.add(np.zeros((len(objectives), 1)), np.array(objectives), measures)
        archives.append(archive)
    empty = GridArchive(solution_dim=1, dims=[4, 4], ranges=[(0, 1), (0, 1)])
    assert colour_range([*archives, empty, None]) == (-4.0, 9.0)
    assert colour_range([empty]) == (None, None)


def small_archive(objectives: list[float]) -> GridArchive:
    """A 4 × 4 archive (16 cells) holding one elite of each objective, in distinct cells."""
    archive = GridArchive(solution_dim=1, dims=[4, 4], ranges=[(0, 1), (0, 1)])
    if objectives:
        cells = np.array([[0.1, 0.1], [0.4, 0.1], [0.6, 0.4], [0.9, 0.9]])[: len(objectives)]
        archive.add(np.zeros((len(objectives), 1)), np.array(objectives), cells)
    return archive


def test_return_profile_counts_cells_at_or_above_each_return() -> None:
    archive = small_archive([1.0, -4.0, 9.0])
    thresholds = np.array([-10.0, -4.0, 0.0, 1.0, 5.0, 9.0, 10.0])
    expected = np.array([3, 3, 2, 2, 1, 1, 0]) / 16 * 100
    np.testing.assert_allclose(archive_profile(archive, thresholds), expected)
    np.testing.assert_array_equal(archive_profile(small_archive([]), thresholds), np.zeros(7))


def test_method_profile_is_the_mean_and_sample_std_over_seeds() -> None:
    runs = [
        SimpleNamespace(archive=small_archive(objectives))
        for objectives in ([1.0, 2.0, 3.0, 4.0], [2.0], [])
    ]
    mean, std = method_profile(runs, np.array([0.0, 2.0, 5.0]))
    shares = np.array([[4, 3, 0], [1, 1, 0], [0, 0, 0]]) / 16 * 100
    np.testing.assert_allclose(mean, shares.mean(axis=0))
    np.testing.assert_allclose(std, shares.std(axis=0, ddof=1))
    one_mean, one_std = method_profile(runs[:1], np.array([0.0]))
    assert one_mean.tolist() == [25.0] and one_std.tolist() == [0.0]


def test_profile_levels_are_fractions_of_the_best_return_in_two_digits() -> None:
    runs = {"A": [SimpleNamespace(archive=small_archive([5815.4, 100.0]))], "B": []}
    assert profile_levels(runs) == [1500.0, 2900.0, 4400.0]
    assert profile_levels({"A": [SimpleNamespace(archive=small_archive([]))]}) == []


def test_html_converts_bold_code_and_images() -> None:
    blocks = [doc.table(["a"], [["**0.01** `x` ![h](heatmaps/a.png) <b>"]])]
    page = doc.to_html(blocks, "t")
    assert '<b>0.01</b> <code>x</code> <img src="heatmaps/a.png" alt="h"> &lt;b&gt;' in page


def test_find_runs_one_level_down(tmp_path: Path) -> None:
    (tmp_path / "runs" / "a").mkdir(parents=True)
    (tmp_path / "runs" / "a" / "config.yaml").write_text("seed: 0\n")
    (tmp_path / "runs" / "notes").mkdir()
    (tmp_path / "empty").mkdir()
    found, missing = find_runs([tmp_path / "runs", tmp_path / "runs" / "a", tmp_path / "empty"])
    assert found == [tmp_path / "runs" / "a"]
    assert [m.path for m in missing] == [tmp_path / "empty"]
    assert "not a run directory" in missing[0].problems[0]
