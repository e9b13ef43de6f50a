"""A trial's metrics are followed by what its ``metrics.csv`` appends, each row once."""

from __future__ import annotations

import os
from pathlib import Path

from qdil.sweeps.follow import MetricsFollower, last_iteration


def write(path: Path, header: str, rows: list[str]) -> None:
    """Replace ``path`` as the tracker does (a new file moved over the old one)."""
    temporary = path.with_suffix(".tmp")
    temporary.write_text("".join(f"{line}\n" for line in [header, *rows]))
    os.replace(temporary, path)


def test_each_row_is_reported_once_through_appends_rewrites_and_truncation(tmp_path) -> None:
    path = tmp_path / "metrics.csv"
    rows = MetricsFollower(path)
    assert rows.rows() == [] and last_iteration(path) == 0  # no file yet
    write(path, "iteration,qd/qd_score", ["1,10"])
    assert rows.rows() == [{"iteration": "1", "qd/qd_score": "10"}]
    with open(path, "a") as file:
        file.write("2,20\n3,3")  # iteration 3 is still being written
    assert [row["iteration"] for row in rows.rows()] == ["2"]
    with open(path, "a") as file:
        file.write("0\n")
    assert rows.rows() == [{"iteration": "3", "qd/qd_score": "30"}]
    assert rows.rows() == []  # nothing new
    # a new metric widens the header: the file is rewritten; only iteration 4 is new
    write(path, "iteration,qd/qd_score,reward/gap", ["1,10,", "2,20,", "3,30,", "4,40,0.5"])
    assert rows.rows() == [{"iteration": "4", "qd/qd_score": "40", "reward/gap": "0.5"}]
    # a resume cuts the rows after its checkpoint and logs them again: not reported twice
    write(path, "iteration,qd/qd_score,reward/gap", ["1,10,", "2,20,"])
    assert rows.rows() == []
    with open(path, "a") as file:
        file.write("3,31,0.1\n4,41,0.2\n5,50,0.3\n")
    assert [row["iteration"] for row in rows.rows()] == ["5"]
    assert last_iteration(path) == 5
