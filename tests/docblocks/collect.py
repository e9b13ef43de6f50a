"""Sybil's collection of the code blocks of README.md and docs/, as a reader meets them.

Each page runs top to bottom in its own copy of the repository's files (a fresh clone, as a
reader has one, without its git history), in a shell of its own (:mod:`shell`):

- ``bash`` blocks run in that shell;
- ``python`` blocks run in one namespace per page, in the shell's current directory;
- a block after ``<!-- save-as: PATH -->`` is a file the page asks the reader to save: it is
  written to PATH (from the shell's current directory) and not run;
- ``<!-- skip: next "reason" -->`` (or ``skip: start``/``skip: end`` around several blocks,
  or ``skip: next if(condition, reason="...")``) skips blocks that need what a test cannot
  have, a GPU, a cluster, a login, downloaded data, and pytest prints the reason (``-rs``);
- other blocks (YAML, TOML, output, trees) are illustrations and are not run.

The items are marked ``docs``: ``pytest -m docs``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Any

import pytest
from sybil import Example, Region, Sybil
from sybil.evaluators.python import PythonEvaluator
from sybil.parsers.abstract.lexers import LexerCollection
from sybil.parsers.markdown import CodeBlockParser, SkipParser
from sybil.parsers.markdown.lexers import DirectiveInHTMLCommentLexer

from .shell import ShellSession

ROOT = Path(__file__).resolve().parents[2]
SAVE_AS = "_docs_save_as"  # the namespace key of the path the next block is saved to


def clone_files(destination: Path) -> None:
    """Copy the repository's tracked files to ``destination``: what a fresh clone holds."""
    try:
        listed = subprocess.run(
            ["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True
        ).stdout.decode()
        files = [name for name in listed.split("\0") if name]
    except (OSError, subprocess.CalledProcessError):  # not a checkout: everything but outputs
        skipped = {".git", ".venv", ".ci-venv", "runs", "wandb", "__pycache__", "build"}
        files = [
            str(p.relative_to(ROOT))
            for p in ROOT.rglob("*")
            if p.is_file() and not skipped.intersection(p.relative_to(ROOT).parts)
        ]
    for name in files:
        source = ROOT / name
        if source.is_file():  # a tracked file deleted in this working tree is not copied
            (destination / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, destination / name)


def opengl() -> bool:
    """Whether headless OpenGL renders here (``qdil render`` needs it)."""
    from qdil.envs.gl import GLUnavailableError, use_gl_backend

    try:
        use_gl_backend()
    except GLUnavailableError:
        return False
    return True


def setup(namespace: dict[str, Any]) -> None:
    """A fresh folder, home directory and shell for one page."""
    root = Path(tempfile.mkdtemp(prefix="qdil-docs-"))
    clone = root / "qdil"
    clone.mkdir()
    clone_files(clone)
    (root / "home").mkdir()
    namespace.update(_docs_root=root, shell=ShellSession(clone, root / "home", root / "state"))
    namespace["opengl"] = opengl


def teardown(namespace: dict[str, Any]) -> None:
    """Remove the page's folder: runs, videos and reports are only the test's."""
    shutil.rmtree(namespace["_docs_root"], ignore_errors=True)


def run_shell(example: Example) -> str | None:
    return example.namespace["shell"].evaluate(example)


def run_python(example: Example) -> None:
    """A Python block, in the page's namespace and the shell's current directory."""
    here = os.getcwd()
    os.chdir(example.namespace["shell"].cwd)
    try:
        PythonEvaluator()(example)
    finally:
        os.chdir(here)


def save(example: Example) -> None:
    """The block after a ``save-as`` comment, written where the reader saves it."""
    path = example.namespace["shell"].cwd / example.namespace.pop(SAVE_AS)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(example.parsed)


class SaveAsParser:
    """``<!-- save-as: PATH -->``: the next code block is a file to save, not to run."""

    def __init__(self) -> None:
        self.lexers = LexerCollection([DirectiveInHTMLCommentLexer("save-as", arguments=r"\S+")])

    def __call__(self, document: Any):
        for lexed in self.lexers(document):
            yield Region(lexed.start, lexed.end, lexed.lexemes["arguments"], self.remember)

    @staticmethod
    def remember(example: Example) -> None:
        example.namespace[SAVE_AS] = example.parsed.strip()


class BlockParser(CodeBlockParser):
    """Blocks of one language: saved after ``save-as``, otherwise run by ``run`` (if any)."""

    def __init__(self, language: str, run: Any = None) -> None:
        super().__init__(language)
        self.run = run

    def evaluate(self, example: Example) -> str | None:
        if SAVE_AS in example.namespace:
            save(example)
            return None
        return self.run(example) if self.run else None


# languages that are run, and those that are only ever saved (files a page shows)
LANGUAGES = {"bash": run_shell, "python": run_python, "yaml": None, "toml": None}

sybil = Sybil(
    parsers=[
        SkipParser(),
        SaveAsParser(),
        *(BlockParser(language, run) for language, run in LANGUAGES.items()),
    ],
    path=str(ROOT),
    # pathlib's match, from the right: pages one and two folders deep; reports are deeper
    patterns=["README.md", "docs/*.md", "docs/*/*.md"],
    excludes=["plugins/*/README.md"],
    setup=setup,
    teardown=teardown,
    name="docs",
)


def skip_at_the_block(item: pytest.Item, report: pytest.TestReport) -> None:
    """A skipped block's report names the page and line, not the skip's machinery."""
    if item.path.suffix == ".md" and report.skipped and isinstance(report.longrepr, tuple):
        report.longrepr = (str(item.path), item.reportinfo()[1], report.longrepr[2])


BLOCK_TIMEOUT = 2400
"""Seconds one block may take: a block that loops over methods and seeds trains tens of runs."""


def mark_docs(items: list[pytest.Item]) -> None:
    """Mark every docs block ``docs``, so that the default run leaves them out."""
    for item in items:
        if item.path.suffix == ".md":
            item.add_marker(pytest.mark.docs)
            item.add_marker(pytest.mark.timeout(BLOCK_TIMEOUT))
