"""benchmarks/probes/absorbing_reading.py reads the protocol's targets from the shipped records."""

from __future__ import annotations

import gzip
import importlib.util
import json
import shutil
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RECORDS = ROOT / "docs/reports/absorbing-evidence/runs"


def _probe(name: str):
    spec = importlib.util.spec_from_file_location(
        name, ROOT / "benchmarks" / "probes" / f"{name}.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclass looks its module up there
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def reading():
    return _probe("absorbing_reading")


def test_walker_seed5_reads_as_the_miss_the_protocol_page_reports(reading):
    rows = {r.run: r for r in reading.readings(RECORDS)}
    # runs without the option (the seeds beside them) are not read against a target
    assert "walker_mcwae-seed3" not in rows
    r = rows["walker_mcwae_absorbing-seed5"]
    assert (r.task, r.seed, r.metric, r.target) == ("Walker2d-v5", 5, "qd_score", 9.6e5)
    assert round(r.value, -3) == 810_000 and not r.hit
    assert round(r.deployable, -3) == 717_000
    assert r.scored_as_required and r.se_pct == pytest.approx(0.68, abs=0.01)
    assert r.commit == "0177ac7"


def test_humanoid_seed1_reads_as_the_protocol_page_reports(reading):
    rows = {r.run: r for r in reading.readings(RECORDS)}
    gail, wqdil = rows["humanoid_gail_absorbing-seed1"], rows["humanoid_mcwae_absorbing-seed1"]
    for r in (gail, wqdil):
        assert (r.task, r.seed, r.metric, r.target) == ("Humanoid-v5", 1, "obj_max", 3000)
        assert r.commit == "0177ac7"
    assert round(gail.value) == 5777 and gail.hit
    # both on 10 episodes per elite, the standard errors 0.91 % and 0.38 %
    assert gail.scored_as_required and wqdil.scored_as_required
    assert (gail.episodes, wqdil.episodes) == (10, 10)
    assert round(wqdil.value) == 1310 and not wqdil.hit
    assert round(wqdil.deployable) == 1310


def test_second_seeds_read_as_the_protocol_page_reports(reading):
    rows = {r.run: r for r in reading.readings(RECORDS)}
    gail, walker = rows["humanoid_gail_absorbing-seed2"], rows["walker_mcwae_absorbing-seed6"]
    assert (gail.task, gail.seed, gail.episodes) == ("Humanoid-v5", 2, 10)
    assert round(gail.value) == 5818 and gail.hit
    assert round(gail.deployable) == 5729
    assert gail.se_pct == pytest.approx(0.59, abs=0.01)
    assert (walker.task, walker.seed, walker.episodes) == ("Walker2d-v5", 6, 5)
    assert round(walker.value, -3) == 884_000 and not walker.hit
    assert round(walker.deployable, -3) == 784_000
    assert walker.se_pct == pytest.approx(0.48, abs=0.01)
    wqdil = rows["humanoid_mcwae_absorbing-seed2"]
    assert round(wqdil.value) == 716 and not wqdil.hit and wqdil.episodes == 10
    for r in (gail, walker, wqdil):
        assert r.scored_as_required and r.commit == "0177ac7"


def test_help_and_a_missing_folder(reading, capsys):
    with pytest.raises(SystemExit) as exit_:
        reading.main(["--help"])
    assert exit_.value.code == 0 and "RECORDS" in capsys.readouterr().out.upper()
    with pytest.raises(SystemExit) as exit_:
        reading.main(["/no/such/records"])
    assert exit_.value.code == 2
    assert "/no/such/records is not a folder of run records" in capsys.readouterr().err


def test_a_hit_and_a_run_scored_otherwise(reading, tmp_path):
    run = tmp_path / "walker_mcwae_absorbing-seed5"
    shutil.copytree(RECORDS / run.name, run)
    record = json.loads((run / "eval.json").read_text())
    record["metrics"]["qd_score"] = 9.6e5  # at the target counts as reaching it
    record["episodes_per_elite"] = 2
    (run / "eval.json").write_text(json.dumps(record))
    (r,) = reading.readings(tmp_path)
    assert r.hit and not r.scored_as_required


def test_humanoid_is_scored_on_10_episodes_once_the_rule_fired(reading, tmp_path):
    run = tmp_path / "humanoid_mcwae_absorbing-seed1"
    shutil.copytree(RECORDS / run.name, run)
    record = json.loads((run / "eval.json").read_text())
    record["qd_score_se"] = 0.005 * record["metrics"]["qd_score"]  # under 1 % either way
    for episodes, required in ((5, False), (10, True)):
        record["episodes_per_elite"] = episodes
        (run / "eval.json").write_text(json.dumps(record))
        (r,) = reading.readings(tmp_path)
        assert r.scored_as_required is required


def test_a_run_not_rescored_is_named(reading, tmp_path):
    run = tmp_path / "humanoid_gail_absorbing-seed1"
    run.mkdir()
    shutil.copy(RECORDS / "walker_mcwae_absorbing-seed5/config.yaml", run)
    named = r"humanoid_gail_absorbing-seed1: no eval\.json; re-score it: .*10 on Humanoid-v5"
    with pytest.raises(ValueError, match=named):
        reading.readings(tmp_path)


def test_training_figures_read_as_the_protocol_page_quotes(reading):
    wqdil = reading.training(RECORDS / "humanoid_mcwae_absorbing-seed2")
    assert (wqdil.since, wqdil.last) == (2, 100)
    assert wqdil.floor[0] == pytest.approx(-2.30, abs=0.005)
    assert wqdil.alive == pytest.approx(0.22, abs=0.005)
    # the steps before a fall paid more in all but 16 iterations, all of them in 38-65
    assert len(wqdil.paid_more) == 83
    assert {i for i in range(2, 101) if i not in wqdil.paid_more} <= set(range(38, 66))
    assert round(wqdil.falls[100], 1) == 6.1 and round(wqdil.critic_gap[100], 1) == 22.1
    assert round(wqdil.best[100]) == 864 and wqdil.best_from == 56
    gail = reading.training(RECORDS / "humanoid_gail_absorbing-seed2")
    assert gail.paid_more == tuple(range(2, 10)) and gail.critic_gap == {}
    assert gail.best_from == 86 and gail.gap[0] > 3  # the floor always well below a step alive
    walker = reading.training(RECORDS / "walker_mcwae_absorbing-seed5", since=11)
    assert walker.floor[:3] == pytest.approx((-3.69, -5.08, -2.40), abs=0.005)
    assert walker.policy == pytest.approx(0.38, abs=0.005)


def test_training_reading_of_a_run_without_falls_and_bad_input(reading, tmp_path, capsys):
    run = tmp_path / "humanoid_gail_absorbing-seed1"
    shutil.copytree(RECORDS / run.name, run)
    kept = run / "metrics.csv.gz"  # records keep it gzipped; the plain file reads the same
    lines = gzip.decompress(kept.read_bytes()).decode().splitlines()
    kept.unlink()
    header = lines[0].split(",")
    before = header.index("survival/reward_before_fall")
    rows = [line.split(",") for line in lines[1:]]
    for row in rows:
        row[before] = ""  # nothing fell: the iteration paid nothing more before a fall
    (run / "metrics.csv").write_text("\n".join([lines[0]] + [",".join(r) for r in rows]))
    assert reading.training(run).paid_more == ()
    reading.main([str(tmp_path), "--training"])
    out = capsys.readouterr().out
    assert "| humanoid_gail_absorbing-seed1 |" in out and "| 0 of 99 |" in out
    with pytest.raises(ValueError, match="no iteration from 500 on"):
        reading.training(run, since=500)
    (run / "metrics.csv").unlink()
    with pytest.raises(ValueError, match=r"humanoid_gail_absorbing-seed1: no metrics\.csv"):
        reading.training(run)
    assert reading.spans([1, 2, 3, 7, 9, 10]) == "1–3, 7, 9–10"


def test_the_match_reading_finds_wqdil_under_gail_on_the_unclipped_humanoid_records():
    """The clip protocol's second target, read on the earlier runs it was written against."""
    true, deployable = _probe("match_reading").matches(
        RECORDS, "humanoid_mcwae_absorbing", "humanoid_gail_absorbing"
    )
    assert sorted(true.method) == [1, 2] and sorted(true.against) == [1, 2]
    mine, theirs = true.means
    assert round(mine, -3) == 150_000 and round(theirs, -3) == 338_000
    assert true.against_std == pytest.approx(7_100, rel=0.02)
    assert not true.protocol_met and not true.ordering_met
    assert deployable.archive == "deployable" and not deployable.ordering_met


def test_the_match_reading_names_a_run_not_rescored(tmp_path: Path):
    run = tmp_path / "humanoid_gail_absorbing-seed3"
    run.mkdir()
    with pytest.raises(ValueError, match=r"seed3: no eval.json; re-score it first"):
        _probe("match_reading").scores(tmp_path, "humanoid_gail_absorbing")
    with pytest.raises(ValueError, match=r"no run named humanoid_mcwae_clip-seedN"):
        _probe("match_reading").scores(tmp_path, "humanoid_mcwae_clip")
