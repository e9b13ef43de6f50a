"""pytest collects the code blocks of README.md and docs/ as the docs test (``pytest -m docs``).

How the blocks run, and what shortens their training: tests/docblocks/collect.py.
"""

from __future__ import annotations

import pytest

from tests.docblocks.collect import mark_docs, skip_at_the_block, sybil

pytest_collect_file = sybil.pytest()


# The files of processes, longest first (durations as `.ci/run` prints them). Each file goes
# whole to one of the two workers (``--dist loadfile``, so their shared runs are made once),
# in this order: started first, the long ones leave no worker idle at the end.
LONGEST_FIRST = (
    "tests/sweeps/test_sweep.py",
    "tests/test_gpu_check.py",
    "tests/cli/test_split_runs.py",
    "tests/cli/test_fit.py",
    "tests/sweeps/test_spec.py",
    "tests/sweeps/test_search.py",
    "tests/tracking/test_wandb.py",
    "tests/cli/test_reproducible_runs.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The docs blocks are marked ``docs``: ``-m docs`` selects them, the default run does not.

    The suite's longest files run first (:data:`LONGEST_FIRST`).
    """
    mark_docs(items)
    rank = {path: number for number, path in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0], len(rank)))


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo):
    """``-rs`` prints a skipped block's page and line with its reason."""
    report = yield
    skip_at_the_block(item, report)
    return report
