"""qdil's maintained benchmarks: ``python benchmarks/NAME.py`` or ``python -m benchmarks.NAME``.

One-off probes whose figures a page quotes live in ``benchmarks/probes/``; the GPU check's
parts in ``benchmarks/gpu/`` (``python -m benchmarks.gpu_check``).
"""
