"""Rules of the repository: the README's commands and CI stay in step, report records are
committable, and every Python file stays short."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def readme_commands() -> list[str]:
    text = (ROOT / "README.md").read_text()
    setup = text.split("## Set up", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```bash\n(.*?)\n```", setup, flags=re.S)


def test_readme_has_exactly_two_setup_commands() -> None:
    commands = readme_commands()
    assert len(commands) == 2
    assert all("\n" not in command for command in commands)


def test_ci_runs_the_readme_test_command() -> None:
    """Every step of the README's test command after the venv, in order, each on a line of
    ``.ci/run`` of its own or joined as the README joins them (CI times install and tests
    apart)."""
    test_command = readme_commands()[1]
    steps = test_command.split(". .venv/bin/activate && ", 1)[1].split(" && ")
    lines = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()]
    ran = [step for line in lines if not line.startswith("#") for step in line.split(" && ")]
    at = [ran.index(step) if step in ran else -1 for step in steps]
    assert -1 not in at, f"{steps[at.index(-1)]!r} is not a command of .ci/run"
    assert at == sorted(at), f".ci/run runs {steps} in another order"


def test_report_records_are_not_ignored_by_git() -> None:
    """``qdil report`` keeps run records in ``<out>/runs/``; they must be committable.

    An unanchored ``runs/`` pattern once ignored every ``docs/reports/*/runs/`` folder, so the
    records that let a report be remade never reached the repository.
    """
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs git and a checkout")
    record = "docs/reports/any-report/runs/any-run/record.json"
    kept = subprocess.run(["git", "check-ignore", "-q", record], cwd=ROOT, check=False)
    assert kept.returncode == 1, f"{record} is ignored by .gitignore"
    run_dir = subprocess.run(["git", "check-ignore", "-q", "runs/any-run"], cwd=ROOT, check=False)
    assert run_dir.returncode == 0, "run directories at the root should stay ignored"


MAX_LINES = 400
"""A Python file of this many lines or more is split by concept (the style guide's target)."""


def test_every_python_file_is_under_400_lines() -> None:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs git and a checkout")
    listed = subprocess.run(
        ["git", "ls-files", "-z", "--", "src", "tests", "benchmarks"],
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split("\0")
    paths = [ROOT / name for name in listed if name.endswith(".py") and (ROOT / name).exists()]
    long = {
        str(path.relative_to(ROOT)): count
        for path in paths
        if (count := len(path.read_text().splitlines())) >= MAX_LINES
    }
    assert not long, f"split these files by concept (lines): {long}"


def test_user_pages_cite_no_tracker_issue_numbers() -> None:
    """Pages speak to users: a reader has no tracker to look an issue number up in."""
    pages = [ROOT / "README.md", *ROOT.glob("docs/*.md"), *ROOT.glob("docs/*/*.md")]
    cited = {
        str(page.relative_to(ROOT)): found
        for page in pages
        if (found := re.findall(r"\b[Ii]ssues? #?\d+", page.read_text()))
    }
    assert not cited, cited
