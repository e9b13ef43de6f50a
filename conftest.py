"""pytest collects the code blocks of README.md and docs/ as the docs test (``pytest -m docs``).

How the blocks run, and what shortens their training: tests/docblocks/collect.py.
"""

from __future__ import annotations

import pytest

from tests.docblocks.collect import mark_docs, skip_at_the_block, sybil

pytest_collect_file = sybil.pytest()


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The docs blocks are marked ``docs``: ``-m docs`` selects them, the default run does not."""
    mark_docs(items)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo):
    """``-rs`` prints a skipped block's page and line with its reason."""
    report = yield
    skip_at_the_block(item, report)
    return report
