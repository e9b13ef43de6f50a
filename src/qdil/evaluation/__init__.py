"""Evaluation: re-scoring archives, paper-style tables, statistics and figures."""
