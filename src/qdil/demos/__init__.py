"""Demonstrations: the format, loading and validation, and generation from an archive."""

from qdil.demos.dataset import DemoSet

__all__ = ["DemoSet"]
