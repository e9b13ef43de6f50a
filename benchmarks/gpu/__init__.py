"""The GPU check's parts: probes of one step or rollout, whole runs, and the page's tables.

``python -m benchmarks.gpu_check`` runs them in order (docs/guides/gpu.md#the-gpu-check).
"""
