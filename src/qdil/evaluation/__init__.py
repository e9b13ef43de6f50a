"""Evaluation: re-scoring archives, paper-style tables, statistics, figures and videos."""
