"""Rules of the repository: the README's commands and CI stay in step, report records are
committable and held once, the tree travels to a GPU, and every Python file stays short."""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOOLS = ROOT / "tools"


def git_files() -> set[Path]:
    """The tracked files of the checkout (skips the test where there is no git checkout)."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs git and a checkout")
    listed = subprocess.run(
        ["git", "ls-files", "-z"], cwd=ROOT, check=True, capture_output=True, text=True
    ).stdout.split("\0")
    # a broken link is listed too (lexists), so that the link test can name it
    return {ROOT / name for name in listed if name and os.path.lexists(ROOT / name)}


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
        ["git", "ls-files", "-z", "--", "src", "tests", "benchmarks", "tools"],
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


def _link_duplicates():
    spec = importlib.util.spec_from_file_location("link_duplicates", TOOLS / "link_duplicates.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_report_records_are_held_once_and_their_links_resolve_inside_the_repository() -> None:
    """A run recorded by several reports is kept once (``tools/link_duplicates.py``), and
    every link of the tracked tree points to a tracked file beside it, so a clone reads them."""
    groups = _link_duplicates().duplicates(ROOT / "docs" / "reports")
    assert not groups, (
        f"{len(groups)} files are held more than once, e.g. {[str(p) for p in groups[0]]}: "
        "run python tools/link_duplicates.py docs/reports"
    )
    tracked = git_files()
    for path in tracked:
        if path.is_symlink():
            target = path.resolve()
            assert target.is_file() and target.is_relative_to(ROOT), f"{path} -> {target}"
            assert target in tracked, f"{path} points to {target}, which git does not track"


def test_the_tracked_tree_leaves_half_of_a_gpu_call_for_wheels() -> None:
    """A call of the GPU machine carries the tree and wheels in 64 MiB (docs/guides/gpu.md):
    the tree stays under 32 MiB, links counted as links."""
    size = sum(path.lstat().st_size for path in git_files())
    assert size <= 32 * 2**20, (
        f"the tracked tree is {size / 2**20:.1f} MiB: keep records light (gzipped tables, "
        "one copy of each run: tools/link_duplicates.py)"
    )


def test_link_duplicates_keeps_the_first_added_copy_and_links_the_rest(tmp_path: Path) -> None:
    module = _link_duplicates()
    data = bytes(range(256)) * 8
    (tmp_path / "a" / "run").mkdir(parents=True)
    (tmp_path / "b" / "run").mkdir(parents=True)
    (tmp_path / "a" / "run" / "metrics.csv.gz").write_bytes(data)
    (tmp_path / "b" / "run" / "metrics.csv.gz").write_bytes(data)
    (tmp_path / "b" / "run" / "other.csv.gz").write_bytes(data[::-1])
    assert module.main([str(tmp_path), "--check"]) == 1
    assert module.main([str(tmp_path)]) == 0
    linked = tmp_path / "b" / "run" / "metrics.csv.gz"
    assert linked.is_symlink() and linked.read_bytes() == data
    assert str(linked.readlink()) == "../../a/run/metrics.csv.gz"  # relative: clones read it
    assert not (tmp_path / "b" / "run" / "other.csv.gz").is_symlink()
    assert module.main([str(tmp_path), "--check"]) == 0
    # an image is not linked: its report's pages show the kept copy, and it goes
    for report in ("a", "b"):
        (tmp_path / report / "curves").mkdir()
        (tmp_path / report / "curves" / "qd.png").write_bytes(data[::-1] * 2)
        (tmp_path / report / "report.md").write_text("![QD-Score](curves/qd.png)\n")
        (tmp_path / report / "report.html").write_text('<img src="curves/qd.png">\n')
    assert module.main([str(tmp_path)]) == 0
    assert not os.path.lexists(tmp_path / "b" / "curves" / "qd.png")
    assert (tmp_path / "b" / "report.md").read_text() == "![QD-Score](../a/curves/qd.png)\n"
    assert (tmp_path / "b" / "report.html").read_text() == '<img src="../a/curves/qd.png">\n'
    assert (tmp_path / "a" / "report.md").read_text() == "![QD-Score](curves/qd.png)\n"
