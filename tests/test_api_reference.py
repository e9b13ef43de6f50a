"""docs/api.md is what tools/api_reference.py writes from today's docstrings."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import qdil

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("api_reference", ROOT / "tools/api_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_api_page_matches_the_docstrings() -> None:
    tool = _tool()
    written = tool.page()
    assert (ROOT / "docs" / "api.md").read_text() == written, (
        "docs/api.md is stale: run python tools/api_reference.py"
    )
    # every name `import qdil` offers has its entry, with its signature where it has one
    for name in qdil.__all__:
        if name != "__version__":
            assert f"### `qdil.{name}`" in written, name
    assert "`Experiment.from_recipe(recipe: str | Path, " in written
    assert "- `RecipeError`: " in written  # a Raises section: the error's type, then why
