"""Sweeps: tables of runs (recipes × seeds × options) as one command, on Ray Tune.

:mod:`~qdil.sweeps.trials` plans and checks the trials, :mod:`~qdil.sweeps.trainable` runs
one (``qdil fit``, then ``qdil eval``), :mod:`~qdil.sweeps.driver` runs them all on Tune.
How to use it: docs/guides/sweeps.md.
"""
