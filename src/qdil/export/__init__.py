"""Gaits out of qdil: elites as policy files (ONNX, ``torch.export``) or a Minari dataset.

Why and how to use them: docs/guides/use-a-gait-outside-qdil.md.
"""

from qdil.export.policies import ExportedPolicy, export_policies
from qdil.export.policy import GaitPolicy

__all__ = ["ExportedPolicy", "GaitPolicy", "export_policies"]
