"""``qdil report --out``: a folder git tracks files in is written only with ``--force``."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from qdil.cli import main

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")


def git(*args: str, cwd: Path) -> None:
    identity = ["-c", "user.name=qdil", "-c", "user.email=qdil@example.org"]
    subprocess.run(["git", *identity, *args], cwd=cwd, check=True, capture_output=True)


@pytest.fixture
def repo(tmp_path: Path) -> Path:
    """A git repository with a report committed under docs/reports/kept."""
    git("init", "-q", cwd=tmp_path)
    kept = tmp_path / "docs" / "reports" / "kept"
    kept.mkdir(parents=True)
    (kept / "report.md").write_text("the committed report\n")
    git("add", ".", cwd=tmp_path)
    git("commit", "-q", "-m", "a report", cwd=tmp_path)
    return tmp_path


def test_a_tracked_out_folder_is_refused_without_force(repo: Path) -> None:
    kept = repo / "docs" / "reports" / "kept"
    with pytest.raises(SystemExit) as refused:
        main(["report", str(repo / "runs"), "--out", str(kept)])
    message = str(refused.value.code)
    assert "git tracks 1 file(s)" in message and "docs/reports/kept/report.md" in message
    assert "--force" in message
    assert [p.name for p in kept.iterdir()] == ["report.md"]
    assert (kept / "report.md").read_text() == "the committed report\n"


def test_force_writes_a_tracked_folder_and_other_folders_need_no_flag(repo: Path) -> None:
    kept = repo / "docs" / "reports" / "kept"
    with pytest.raises(SystemExit, match="no run could be included"):  # the report is made
        main(["report", str(repo / "runs"), "--out", str(kept), "--force"])
    assert (kept / "report.md").read_text() != "the committed report\n"
    for out in (repo / "report", repo / "docs" / "reports" / "new", repo.parent / "outside"):
        with pytest.raises(SystemExit, match="no run could be included"):
            main(["report", str(repo / "runs"), "--out", str(out)])
        assert (out / "report.md").is_file()
