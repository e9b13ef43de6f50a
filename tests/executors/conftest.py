"""Fixtures of the executor tests."""

from __future__ import annotations

from typing import Any

import pytest
from executor_helpers import run_phases


@pytest.fixture(scope="session")
def local_outputs() -> list[Any]:
    """The local executor's outputs, the reference of every other executor."""
    return run_phases(None)
