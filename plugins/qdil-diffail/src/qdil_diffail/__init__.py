"""qdil-diffail: DiffAIL (Wang et al., AAAI 2024) as a qdil reward plugin (``diffail``)."""

from qdil_diffail.model import DiffAIL

__all__ = ["DiffAIL"]
