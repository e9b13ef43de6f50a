"""Demonstration sets shipped with qdil (``walker2d.npz``, ``halfcheetah.npz``).

Made by qdil's own PPGA-trueReward runs with ``qdil demos``; each file's header holds its
provenance (run, recipe, seed, code version, chosen elites). Recipes name them by stem:
``demos.path: walker2d``.
"""
