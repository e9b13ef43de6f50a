"""The report's numbers: the main table, Tukey HSD tests, and the rows of its CSV files.

Rows are mean ± sample std over seeds of each method's final metrics (:mod:`qdil.evaluation.report`
says which runs and which archives); the Tukey HSD test compares the raw QD-Scores.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from qdil.evaluation.methods import DISPLAY_NAMES
from qdil.evaluation.ratios import ratio_of_means, seeds_to_resolve
from qdil.evaluation.runs import Groups, RunResult
from qdil.evaluation.stats import (
    Comparison,
    TukeyResult,
    format_mean_std,
    summarize,
    tukey,
)

TABLE_METRICS: tuple[tuple[str, str, str, float], ...] = (
    ("qd_score", "QD-Score", "sci", 1.0),
    ("qd_score_offset", "QD-Score (offset)", "sci", 1.0),
    ("coverage", "Cov(%)", "fixed", 100.0),
    ("obj_max", "Best", "int", 1.0),
    ("obj_mean", "Avg", "int", 1.0),
)
"""(metric key, column title, number style, scale) of the main table."""


ARCHIVES = {"true": "true-keyed (paper)", "deployable": "deployable"}
"""The policy archives a report tables: :attr:`RunResult.metrics` and ``.deployable``."""


def metric_values(
    runs: Sequence[RunResult], key: str, scale: float = 1.0, archive: str = "true"
) -> np.ndarray:
    """One final metric of each run's ``true`` or ``deployable`` archive, shape ``(len(runs),)``."""
    found = [run.metrics if archive == "true" else run.deployable for run in runs]
    return np.array([scale * metrics.get(key, math.nan) for metrics in found], dtype=np.float64)


def scored(runs: Sequence[RunResult], archive: str = "true") -> list[RunResult]:
    """The runs that have ``archive`` (``true`` or ``deployable``).

    Every run has its true-keyed archive; a run whose checkpoint predates the deployable
    archive has none, and is left out of that archive's means instead of making them NaN.
    """
    return [run for run in runs if archive == "true" or run.deployable]


def _short(task: str) -> str:
    """``Walker2d`` for ``Walker2d-v5``, ``Walker2d (euler)`` for another integrator's."""
    name, _, changed = task.partition(" ")
    return name.split("-v")[0] + (f" {changed}" if changed else "")


def _count(runs: Sequence[RunResult]) -> str:
    """Seeds of a group, ``*`` if some are unfinished."""
    if not runs:
        return "–"
    return f"{len(runs)}*" if any(run.unfinished for run in runs) else str(len(runs))


def main_table(groups: Groups, archive: str = "true") -> tuple[list[str], list[list[str]]]:
    """The paper's main table: rows = methods, per task n, QD-Score, Cov(%), Best, Avg.

    Args:
        groups: included runs by task and method.
        archive: ``true`` (the paper's true-keyed archives) or ``deployable``.

    Returns:
        Header and rows of text cells (``mean ± std`` over the seeds that have ``archive``,
        counted by ``n``; ``n`` has a ``*`` when the group includes unfinished runs).
    """
    columns = [m for m in TABLE_METRICS if m[0] != "qd_score_offset"]
    header = ["Method"]
    for task in groups:
        header += [f"{_short(task)} n"] + [f"{_short(task)} {title}" for _, title, _, _ in columns]
    methods = _methods(groups)
    rows = []
    for method in methods:
        row = [method]
        for runs_by_method in groups.values():
            runs = scored(runs_by_method.get(method, []), archive)
            row.append(_count(runs))
            for key, _, style, scale in columns:
                values = metric_values(runs, key, scale, archive)
                cell = format_mean_std(summarize(values), style)
                row.append(cell if runs and not np.isnan(values).all() else "–")
        rows.append(row)
    return header, rows


def offset_table(groups: Groups) -> tuple[list[str], list[list[str]]]:
    """Offset QD-Score (PPGA's convention): rows = methods, one column per task."""
    header = ["Method"] + [f"{_short(task)} QD-Score (offset)" for task in groups]
    rows = []
    for method in _methods(groups):
        row = [method]
        for runs_by_method in groups.values():
            runs = runs_by_method.get(method, [])
            summary = summarize(metric_values(runs, "qd_score_offset"))
            row.append(format_mean_std(summary, "sci") if runs else "–")
        rows.append(row)
    return header, rows


def _methods(groups: Groups) -> list[str]:
    methods: list[str] = []
    for runs_by_method in groups.values():
        methods += [m for m in runs_by_method if m not in methods]
    first = DISPLAY_NAMES["true_reward"]
    return sorted(methods, key=lambda m: (not m.startswith(first), m.lower()))


def table_records(groups: Groups, archive: str = "true") -> list[dict[str, Any]]:
    """One record per task × method with mean, std and n of every table metric (CSV rows).

    Args:
        groups: included runs by task and method.
        archive: ``true`` or ``deployable`` (``n`` and ``seeds`` count the runs that have it).
    """
    records = []
    for task, runs_by_method in groups.items():
        for method, group in runs_by_method.items():
            runs = scored(group, archive)
            record: dict[str, Any] = {
                "task": task,
                "method": method,
                "n": len(runs),
                "seeds": " ".join(str(r.seed) for r in runs),
                "unfinished": sum(r.unfinished for r in runs),
                "corrected": sum(r.source.startswith("corrected") for r in runs),
            }
            for key, _, _, scale in TABLE_METRICS:
                name = "coverage_pct" if key == "coverage" else key
                summary = summarize(metric_values(runs, key, scale, archive))
                record[f"{name}_mean"], record[f"{name}_std"] = summary.mean, summary.std
            records.append(record)
    return records


RATIO_REFERENCES = (DISPLAY_NAMES["true_reward"], DISPLAY_NAMES["gail"])
"""The methods every other method's QD-Score is divided by: the expert and GAIL."""


RATIO_SCORES = {"qd_score": "raw", "qd_score_offset": "offset"}
"""The QD-Scores ratios are taken of: the paper's raw sum of returns, and PPGA's offset one
(positive, so its ratios are defined where raw QD-Scores lie near zero)."""


def ratio_records(groups: Groups) -> list[dict[str, Any]]:
    """QD-Score ratios of every method to the expert and to GAIL, both archives, raw and offset.

    One convention: the ratio of the means over seeds, with a 95 % bootstrap interval
    (:func:`qdil.evaluation.ratios.ratio_of_means`; unbounded where the reference's mean may
    be zero), and the seeds per method a t-test would need to find the gap
    (:func:`qdil.evaluation.ratios.seeds_to_resolve`).

    Returns:
        One record per task, archive, QD-Score, method and reference present (CSV rows).
    """
    records = []
    for task, runs_by_method in groups.items():
        for archive in ARCHIVES:
            for key, score in RATIO_SCORES.items():
                for reference in RATIO_REFERENCES:
                    if reference not in runs_by_method:
                        continue
                    reference_runs = scored(runs_by_method[reference], archive)
                    below = metric_values(reference_runs, key, 1.0, archive)
                    for method, runs in runs_by_method.items():
                        above = metric_values(scored(runs, archive), key, 1.0, archive)
                        if method == reference or not len(above) or not len(below):
                            continue
                        ratio = ratio_of_means(above, below)
                        records.append(
                            {
                                "task": task,
                                "archive": archive,
                                "qd_score": score,
                                "ratio": f"{method} / {reference}",
                                "value": ratio.value,
                                "low": ratio.low,
                                "high": ratio.high,
                                "bounded": ratio.bounded,
                                "n": f"{ratio.n_numerator}/{ratio.n_denominator}",
                                "seeds_to_resolve": seeds_to_resolve(above, below),
                            }
                        )
    return records


def ratio_table(records: Sequence[Mapping[str, Any]]) -> tuple[list[str], list[list[str]]]:
    """The ratio records as text: ``0.86 [0.73, 1.03]`` and the seeds a gap would need."""
    header = ["Task", "Archive", "QD-Score", "Ratio", "value [95 % interval]", "n"]
    header.append("seeds to resolve")
    rows = []
    for r in records:
        cell = f"{r['value']:.2f}"
        if not r["bounded"]:
            cell += ", unbounded: the reference's mean may be 0"
        elif not math.isnan(r["low"]):
            cell += f" [{r['low']:.2f}, {r['high']:.2f}]"
        elif not math.isnan(r["value"]):
            cell += ", no interval: one seed"
        needed = "–" if r["seeds_to_resolve"] is None else str(r["seeds_to_resolve"])
        archive = ARCHIVES[r["archive"]]
        rows.append([_short(r["task"]), archive, r["qd_score"], r["ratio"], cell, r["n"], needed])
    return header, rows


def tukey_tests(
    groups: Groups, reference: str | None = None, key: str = "qd_score"
) -> dict[str, TukeyResult]:
    """Tukey HSD on a QD-Score (default: the raw one) between the methods of each task.

    Args:
        groups: included runs by task and method.
        reference: keep only pairs with this method, oriented so that it is ``group2``
            (the paper's layout: ``+`` means the reference is better).
        key: the final metric compared, ``qd_score`` or ``qd_score_offset``.

    Returns:
        Task -> comparisons and notes.
    """
    results = {}
    for task, runs_by_method in groups.items():
        values = {m: metric_values(runs, key) for m, runs in runs_by_method.items()}
        result = tukey(values)
        if reference is not None:
            result.comparisons = _orient(result.comparisons, reference)
            if reference not in values:
                result.notes.append(f"reference method {reference} has no runs on {task}")
        results[task] = result
    return results


def _orient(comparisons: Sequence[Comparison], reference: str) -> list[Comparison]:
    oriented = []
    for c in comparisons:
        if c.group2 == reference:
            oriented.append(c)
        elif c.group1 == reference:
            oriented.append(
                Comparison(c.group2, c.group1, c.mean2, c.mean1, -c.diff, c.pvalue, c.n2, c.n1)
            )
    return oriented


def format_pvalue(pvalue: float) -> str:
    """A p-value with 4 decimals, bold when ``p ≤ 0.05``."""
    if not math.isfinite(pvalue):
        return "nan"
    text = f"{pvalue:.4f}" if pvalue >= 1e-4 else "<0.0001"
    return f"**{text}**" if pvalue <= 0.05 else text


def tukey_table(results: Mapping[str, TukeyResult]) -> tuple[list[str], list[list[str]]]:
    """The paper's Tukey table: group1, group2, then sign and p-value for each task."""
    pairs: list[tuple[str, str]] = []
    for result in results.values():
        pairs += [
            (c.group1, c.group2) for c in result.comparisons if (c.group1, c.group2) not in pairs
        ]
    header = ["group1", "group2"]
    for task in results:
        header += [f"{_short(task)} sign", f"{_short(task)} p"]
    rows = []
    for pair in pairs:
        row = list(pair)
        for result in results.values():
            found = [c for c in result.comparisons if (c.group1, c.group2) == pair]
            row += [found[0].sign, format_pvalue(found[0].pvalue)] if found else ["–", "–"]
        rows.append(row)
    return header, rows


def tukey_records(results: Mapping[str, TukeyResult], score: str = "raw") -> list[dict[str, Any]]:
    """One record per task and pair (CSV rows), ``score`` naming the QD-Score compared."""
    return [
        {
            "task": task,
            "qd_score": score,
            "group1": c.group1,
            "group2": c.group2,
            "n1": c.n1,
            "n2": c.n2,
            "mean1": c.mean1,
            "mean2": c.mean2,
            "diff": c.diff,
            "sign": c.sign,
            "pvalue": c.pvalue,
            "significant": c.significant,
        }
        for task, result in results.items()
        for c in result.comparisons
    ]


def run_records(runs: Sequence[RunResult]) -> list[dict[str, Any]]:
    """One record per run directory, left out ones included (``runs.csv`` rows)."""
    records = []
    for run in runs:
        record: dict[str, Any] = {
            "path": str(run.path),
            "task": run.task_label or "",
            "method": run.method or "",
            "seed": "" if run.seed is None else run.seed,
            "status": run.status,
            "iteration": "" if run.iteration is None else run.iteration,
            "last_logged": "" if run.last_logged is None else run.last_logged,
            "target": "" if run.target is None else run.target,
            "source": run.source,
            "reason": "; ".join(run.problems + run.notes),
        }
        for key, _, _, scale in (*TABLE_METRICS, ("num_elites", "", "", 1.0)):
            name = "coverage_pct" if key == "coverage" else key
            record[name] = scale * run.metrics[key] if key in run.metrics else ""
        for key, _, _, scale in (*TABLE_METRICS, ("num_elites", "", "", 1.0)):
            name = "coverage_pct" if key == "coverage" else key
            value = run.deployable.get(key)
            record[f"deployable_{name}"] = "" if value is None else scale * value
        record["deployable_source"] = run.deployable_source
        records.append(record)
    return records


def write_csv(path: Path, records: Sequence[Mapping[str, Any]], header: Sequence[str]) -> None:
    """Write records as CSV (floats at full precision)."""
    with open(path, "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(header))
        writer.writeheader()
        writer.writerows(records)
