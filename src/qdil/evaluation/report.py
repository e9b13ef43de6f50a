"""``qdil report``: the paper's tables, Tukey HSD tests and figures from run directories.

Which runs go in:

- A given path is a run directory if it holds ``config.yaml``; otherwise every directory
  directly inside it that holds ``config.yaml`` is a run. A path that is neither is listed as
  left out.
- A run is **left out** when its ``config.yaml`` is unreadable or names no ``env.task``,
  when it has no ``metrics.csv`` (or the file has no rows), or when it has no readable
  checkpoint (``checkpoints/last.pt``). Left-out runs are listed, with the reason, in the
  report's "Runs left out / unfinished" section and in ``runs.csv``; they are never dropped
  silently.
- A run is **unfinished** when its last logged iteration or its checkpoint's iteration is
  below ``qd.iterations``. Unfinished runs that have a checkpoint are still included
  (tables, tests, figures) at the iteration of their checkpoint, flagged in the tables
  (``n`` reads ``3*``) and listed in the same section.

Which numbers: a run's final metrics come from the corrected archive of ``qdil eval``
(``eval.json`` and ``corrected_archive.pkl``, decision D12) when it exists and was made from
the run's current checkpoint, otherwise from the training true-return archive of the
checkpoint; the run list says which source each run used. Learning curves come from
``metrics.csv`` (the training archive at every iteration). Both QD-Scores are reported
(decision D10): the raw QD-Score (Σ true returns; QDIL/WQDIL papers) and the offset
QD-Score (PPGA's convention, :data:`qdil.qd.archives.QD_OFFSETS`).

Files written into the output folder: ``report.md`` and ``report.html`` (everything on one
page), ``table.md`` / ``table.csv`` (main table), ``tukey.md`` / ``tukey.csv``,
``runs.csv`` (every run, its status and final metrics), ``heatmaps/*.png`` and
``curves/*.png``.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from ribs.archives import GridArchive

from qdil.evaluation import document as doc
from qdil.evaluation.runs import (
    DISPLAY_NAMES,
    Groups,
    RunResult,
    collect_runs,
    flag_duplicate_seeds,
    group_runs,
)
from qdil.evaluation.stats import (
    Comparison,
    TukeyResult,
    align_curves,
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

CURVE_METRICS: tuple[tuple[str, str, float], ...] = (
    ("qd/qd_score", "QD-Score", 1.0),
    ("qd/coverage", "coverage (%)", 100.0),
    ("qd/obj_max", "best return", 1.0),
    ("qd/obj_mean", "average return", 1.0),
)
"""(metrics.csv column, axis label, scale) of the learning curves."""


def metric_values(runs: Sequence[RunResult], key: str, scale: float = 1.0) -> np.ndarray:
    """One final metric of each run, shape ``(len(runs),)``."""
    return np.array([scale * run.metrics.get(key, math.nan) for run in runs], dtype=np.float64)


def _short(task: str) -> str:
    return task.split("-v")[0]


def _count(runs: Sequence[RunResult]) -> str:
    """Seeds of a group, ``*`` if some are unfinished."""
    if not runs:
        return "–"
    return f"{len(runs)}*" if any(run.unfinished for run in runs) else str(len(runs))


def main_table(groups: Groups) -> tuple[list[str], list[list[str]]]:
    """The paper's main table: rows = methods, per task n, QD-Score, Cov(%), Best, Avg.

    Returns:
        Header and rows of text cells (``mean ± std`` over seeds; ``n`` has a ``*`` when the
        group includes unfinished runs).
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
            runs = runs_by_method.get(method, [])
            row.append(_count(runs))
            for key, _, style, scale in columns:
                cell = format_mean_std(summarize(metric_values(runs, key, scale)), style)
                row.append(cell if runs else "–")
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


def table_records(groups: Groups) -> list[dict[str, Any]]:
    """One record per task × method with mean, std and n of every table metric (CSV rows)."""
    records = []
    for task, runs_by_method in groups.items():
        for method, runs in runs_by_method.items():
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
                summary = summarize(metric_values(runs, key, scale))
                record[f"{name}_mean"], record[f"{name}_std"] = summary.mean, summary.std
            records.append(record)
    return records


def tukey_tests(groups: Groups, reference: str | None = None) -> dict[str, TukeyResult]:
    """Tukey HSD on the raw QD-Score between the methods of each task.

    Args:
        groups: included runs by task and method.
        reference: keep only pairs with this method, oriented so that it is ``group2``
            (the paper's layout: ``+`` means the reference is better).

    Returns:
        Task -> comparisons and notes.
    """
    results = {}
    for task, runs_by_method in groups.items():
        values = {m: metric_values(runs, "qd_score") for m, runs in runs_by_method.items()}
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


def tukey_records(results: Mapping[str, TukeyResult]) -> list[dict[str, Any]]:
    """One record per task and pair (CSV rows)."""
    return [
        {
            "task": task,
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


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "run"


def colour_range(archives: Iterable[GridArchive | None]) -> tuple[float | None, float | None]:
    """Smallest and largest objective over archives: one colour scale for a task."""
    objectives = [a.data("objective") for a in archives if a is not None and len(a)]
    if not objectives:
        return None, None
    values = np.concatenate(objectives)
    return float(values.min()), float(values.max())


def plot_heatmaps(groups: Groups, out: Path) -> dict[Path, str]:
    """Save a heatmap of every run's final archive under ``out/heatmaps``.

    Returns:
        Run directory -> PNG path relative to ``out``.
    """
    import matplotlib.pyplot as plt

    from qdil.evaluation.plots import archive_heatmap

    (out / "heatmaps").mkdir(parents=True, exist_ok=True)
    made: dict[Path, str] = {}
    for task, runs_by_method in groups.items():
        vmin, vmax = colour_range(r.archive for runs in runs_by_method.values() for r in runs)
        for method, runs in runs_by_method.items():
            for run in runs:
                name = f"heatmaps/{_slug(task)}__{_slug(method)}__{_slug(run.path.name)}"
                while f"{name}.png" in made.values():
                    name += "_"
                title = f"{method} · seed {run.seed} · {task}\n{run.source}"
                try:
                    figure = archive_heatmap(run.archive, title=title, vmin=vmin, vmax=vmax)
                except ValueError as error:  # pyribs draws 1-D and 2-D grids only
                    run.notes.append(f"no heatmap: {error}")
                    continue
                figure.savefig(out / f"{name}.png", dpi=100)
                plt.close(figure)
                made[run.path] = f"{name}.png"
    return made


def method_curves(
    runs: Sequence[RunResult], key: str, scale: float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and std over a method's seeds of one ``metrics.csv`` column.

    Returns:
        ``(iterations, mean, std)``, shapes ``(T,)``, on the iterations all seeds have.
    """
    curves = [(r.curves[key][0], scale * r.curves[key][1]) for r in runs if key in r.curves]
    if len(curves) < len(runs):
        return np.zeros(0), np.zeros(0), np.zeros(0)
    return align_curves(curves)


def plot_curves(groups: Groups, out: Path) -> dict[str, list[tuple[str, str]]]:
    """Save learning curves (one PNG per task and metric) under ``out/curves``.

    Returns:
        Task -> ``(metric label, PNG path relative to out)`` pairs.
    """
    import matplotlib.pyplot as plt

    from qdil.evaluation.plots import learning_curves

    (out / "curves").mkdir(parents=True, exist_ok=True)
    made: dict[str, list[tuple[str, str]]] = {}
    for task, runs_by_method in groups.items():
        for key, label, scale in CURVE_METRICS:
            lines = {}
            for method, runs in runs_by_method.items():
                steps, mean, std = method_curves(runs, key, scale)
                if len(steps):
                    lines[method] = (steps, mean, std, len(runs))
            figure = learning_curves(lines, title=f"{task}: {label}", ylabel=label)
            name = f"curves/{_slug(task)}__{_slug(key.split('/')[-1])}.png"
            figure.savefig(out / name, dpi=100)
            plt.close(figure)
            made.setdefault(task, []).append((label, name))
    return made


def run_records(runs: Sequence[RunResult]) -> list[dict[str, Any]]:
    """One record per run directory, left out ones included (``runs.csv`` rows)."""
    records = []
    for run in runs:
        record: dict[str, Any] = {
            "path": str(run.path),
            "task": run.task or "",
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
        records.append(record)
    return records


def write_csv(path: Path, records: Sequence[Mapping[str, Any]], header: Sequence[str]) -> None:
    """Write records as CSV (floats at full precision)."""
    with open(path, "w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(header))
        writer.writeheader()
        writer.writerows(records)


@dataclass
class Report:
    """What :func:`write_report` made.

    Attributes:
        out: the output folder.
        runs: every run found (included and left out).
        groups: included runs by task and method.
        tukey: Tukey HSD results by task.
        main_table: the main table as Markdown.
        files: every file written, relative to ``out``.
    """

    out: Path
    runs: list[RunResult]
    groups: Groups
    tukey: dict[str, TukeyResult]
    main_table: str
    files: list[str]


def _problem_rows(runs: Sequence[RunResult]) -> list[list[str]]:
    return [
        [f"`{run.path}`", run.status, "; ".join(run.problems + run.notes)]
        for run in runs
        if not run.included or run.unfinished or run.notes
    ]


def _image_rows(
    groups: Groups, task: str, heatmaps: Mapping[Path, str]
) -> tuple[list[str], list[list[str]]]:
    runs_by_method = groups[task]
    width = max(len(runs) for runs in runs_by_method.values())
    header = ["Method"] + [f"run {i + 1}" for i in range(width)]
    rows = []
    for method, runs in runs_by_method.items():
        cells = [
            f"![{method} seed {r.seed}]({heatmaps[r.path]})" if r.path in heatmaps else "–"
            for r in runs
        ]
        rows.append([method, *cells, *[""] * (width - len(cells))])
    return header, rows


def _sources(groups: Groups) -> list[str]:
    lines = []
    for task, runs_by_method in groups.items():
        for method, runs in runs_by_method.items():
            corrected = sum(r.source.startswith("corrected") for r in runs)
            lines.append(
                f"{task} / {method}: {corrected} of {len(runs)} run(s) from corrected archives "
                f"(`qdil eval`), {len(runs) - corrected} from training archives"
            )
    return lines


def build_document(
    report: Report, heatmaps: Mapping[Path, str], curves: Mapping[str, list[tuple[str, str]]]
) -> list[doc.Block]:
    """The blocks of ``report.md`` / ``report.html``."""
    runs, groups = report.runs, report.groups
    included = [r for r in runs if r.included]
    blocks = [
        doc.heading("qdil report", 1),
        doc.text(
            f"{len(runs)} run(s): {len(included)} included "
            f"({sum(r.unfinished for r in included)} unfinished), "
            f"{len(runs) - len(included)} left out. Numbers are mean ± sample std "
            "(ddof=1) over seeds; QD-Score is the raw sum of true returns (QDIL/WQDIL papers), "
            "the offset QD-Score adds PPGA's per-step offset × episode length; Cov is the "
            "percentage of filled cells, Best and Avg the best and mean elite returns."
        ),
        doc.heading("Main results"),
    ]
    if groups:
        blocks += [doc.table(*main_table(groups))]
        blocks += [doc.text("n with `*`: the group includes unfinished runs (see below).")]
        blocks += [doc.heading("Offset QD-Score (PPGA convention)", 3)]
        blocks += [doc.table(*offset_table(groups))]
        blocks += [doc.heading("Sources of the final metrics", 3), doc.bullets(_sources(groups))]
    else:
        blocks += [doc.text("No run could be included.")]
    blocks += [doc.heading("Tukey HSD test of the raw QD-Score")]
    blocks += [
        doc.text(
            "Sign: `+` when group2's mean is higher than group1's. Bold: p ≤ 0.05 (Tukey-adjusted)."
        )
    ]
    header, rows = tukey_table(report.tukey)
    blocks += [doc.table(header, rows)] if rows else [doc.text("No pair could be tested.")]
    notes = [f"{task}: {note}" for task, res in report.tukey.items() for note in res.notes]
    blocks += [doc.bullets(notes)] if notes else []
    blocks += [doc.heading("Learning curves")]
    blocks += [
        doc.text(
            "Training archive (`metrics.csv`), mean over seeds with a ±std band; each method "
            "on the iterations all of its seeds logged."
        )
    ]
    for task, images in curves.items():
        blocks += [doc.heading(task, 3), doc.table(*_curve_row(images))]
    blocks += [doc.heading("Archive heatmaps")]
    for task in groups:
        vmin, vmax = colour_range(r.archive for rs in groups[task].values() for r in rs)
        scale = "empty archives" if vmin is None else f"colour scale {vmin:.4g} to {vmax:.4g}"
        blocks += [doc.heading(task, 3), doc.text(f"Final archives; {scale} for every run.")]
        blocks += [doc.table(*_image_rows(groups, task, heatmaps))]
    blocks += [doc.heading("Runs"), doc.table(*_runs_table(runs))]
    blocks += [doc.heading("Runs left out / unfinished")]
    blocks += [
        doc.text("Also listed: included runs with remarks (stale `eval.json`, shared seeds).")
    ]
    problems = _problem_rows(runs)
    header = ["run", "status", "reason"]
    blocks += [doc.table(header, problems)] if problems else [doc.text("None.")]
    return blocks


def _curve_row(images: Sequence[tuple[str, str]]) -> tuple[list[str], list[list[str]]]:
    return [label for label, _ in images], [[f"![{label}]({path})" for label, path in images]]


def _runs_table(runs: Sequence[RunResult]) -> tuple[list[str], list[list[str]]]:
    header = ["run", "task", "method", "seed", "iteration", "status", "source"]
    rows = [
        [
            f"`{run.path}`",
            run.task or "–",
            run.method or "–",
            "–" if run.seed is None else str(run.seed),
            f"{run.iteration if run.iteration is not None else '–'} / {run.target or '–'}",
            run.status,
            run.source or "–",
        ]
        for run in runs
    ]
    return header, rows


def write_report(
    paths: Iterable[str | Path],
    out: str | Path,
    labels: Mapping[str | Path, str] | None = None,
    reference: str | None = None,
) -> Report:
    """Collect runs and write the whole report into ``out``.

    Args:
        paths: run directories, or folders whose direct sub-directories are runs.
        out: output folder (created).
        labels: run directory -> method label, overriding :func:`method_label`.
        reference: method the Tukey table compares every other method with (all pairs if
            ``None``).

    Returns:
        What was written (also the data behind it).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    runs = collect_runs(paths, labels)
    groups = group_runs(runs)
    flag_duplicate_seeds(groups)
    results = tukey_tests(groups, reference)
    table_md = doc.markdown_table(*main_table(groups)) if groups else ""
    report = Report(out, runs, groups, results, table_md, [])
    heatmaps = plot_heatmaps(groups, out)
    curves = plot_curves(groups, out)
    _write_files(report, heatmaps, curves)
    return report


def _write_files(
    report: Report, heatmaps: Mapping[Path, str], curves: Mapping[str, list[tuple[str, str]]]
) -> None:
    out, groups = report.out, report.groups
    table_md = report.main_table + "\n\n" + doc.markdown_table(*offset_table(groups)) + "\n"
    (out / "table.md").write_text(table_md if groups else "No run could be included.\n")
    records = table_records(groups)
    header = list(records[0]) if records else ["task", "method", "n"]
    write_csv(out / "table.csv", records, header)
    tukey_header, tukey_rows = tukey_table(report.tukey)
    notes = [f"- {t}: {n}" for t, res in report.tukey.items() for n in res.notes]
    tukey_md = doc.markdown_table(tukey_header, tukey_rows) if tukey_rows else "No pair tested."
    (out / "tukey.md").write_text(tukey_md + "\n\n" + "\n".join(notes) + "\n")
    fields = ["task", "group1", "group2", "n1", "n2", "mean1", "mean2", "diff", "sign"]
    write_csv(out / "tukey.csv", tukey_records(report.tukey), [*fields, "pvalue", "significant"])
    run_rows = run_records(report.runs)
    write_csv(out / "runs.csv", run_rows, list(run_rows[0]) if run_rows else ["path"])
    blocks = build_document(report, heatmaps, curves)
    (out / "report.md").write_text(doc.to_markdown(blocks))
    (out / "report.html").write_text(doc.to_html(blocks, "qdil report"))
    written = ["report.md", "report.html", "table.md", "table.csv", "tukey.md", "tukey.csv"]
    written += ["runs.csv", *heatmaps.values()]
    written += [path for images in curves.values() for _, path in images]
    report.files = written
