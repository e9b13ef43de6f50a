"""``qdil report``: the paper's tables, Tukey HSD tests and figures from run directories.

:func:`write_report` collects the runs (:mod:`qdil.evaluation.runs`), has
:mod:`qdil.evaluation.tables`, :mod:`qdil.evaluation.figures` and :mod:`qdil.evaluation.page`
make the numbers, figures and page, writes the files and keeps a record of every run.
Which runs go in, which numbers, which files: docs/guides/reproduce-paper-results.md.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path

from qdil.evaluation import document as doc
from qdil.evaluation.configurations import flag_duplicate_seeds, separate_configurations
from qdil.evaluation.figures import (
    CURVE_METRICS,
    HeatmapGrid,
    colour_range,
    method_curves,
    plot_curves,
    plot_heatmaps,
    plot_profiles,
)
from qdil.evaluation.gallery import VideoSettings, make_gallery
from qdil.evaluation.page import Report, build_document
from qdil.evaluation.profiles import profile_records
from qdil.evaluation.records import Record, write_record
from qdil.evaluation.runs import RunResult, collect_runs, group_runs
from qdil.evaluation.tables import (
    TABLE_METRICS,
    format_pvalue,
    main_table,
    metric_values,
    offset_table,
    ratio_records,
    run_records,
    table_records,
    tukey_records,
    tukey_table,
    tukey_tests,
    write_csv,
)
from qdil.provenance import provenance

# the report's public names, importable from here as before the split
__all__ = [
    "CURVE_METRICS",
    "TABLE_METRICS",
    "Report",
    "build_document",
    "colour_range",
    "format_pvalue",
    "main_table",
    "method_curves",
    "metric_values",
    "offset_table",
    "plot_curves",
    "plot_heatmaps",
    "run_records",
    "table_records",
    "tukey_records",
    "tukey_table",
    "tukey_tests",
    "write_csv",
    "write_report",
]


def write_report(
    paths: Iterable[str | Path],
    out: str | Path,
    labels: Mapping[str | Path, str] | None = None,
    reference: str | None = None,
    records: bool = True,
    videos: VideoSettings | None = None,
) -> Report:
    """Collect runs and write the whole report into ``out``.

    Args:
        paths: run directories, or folders whose direct sub-directories are runs.
        out: output folder (created).
        labels: run directory -> method label, overriding :func:`method_label`.
        reference: method the Tukey table compares every other method with (all pairs if
            ``None``).
        records: keep a record of every included run in ``out/runs/`` (see
            :mod:`qdil.evaluation.records`).
        videos: how many videos of elites per run, and how they are drawn, for the HTML
            page (``None``: none; ``qdil report`` makes 6 per run).

    Returns:
        What was written (also the data behind it).
    """
    made_by = provenance()  # before this report rewrites anything of its tree
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    runs = collect_runs(paths, labels)
    separate_configurations(runs)  # a row pools one configuration (every key but the seed)
    groups = group_runs(runs)
    flag_duplicate_seeds(groups)
    results = tukey_tests(groups, reference)
    table_md = doc.markdown_table(*main_table(groups)) if groups else ""
    report = Report(out, runs, groups, results, table_md, [])
    report.tukey_offset = tukey_tests(groups, reference, "qd_score_offset")
    grids: dict[Path, HeatmapGrid] = {}
    heatmaps = plot_heatmaps(groups, out, grids)
    report.gallery = make_gallery(groups, out, heatmaps, videos or VideoSettings(count=0))
    curves = plot_curves(groups, out)
    profiles = plot_profiles(groups, out)
    _write_files(report, heatmaps, curves, profiles, grids)
    if records:
        report.files += keep_records(runs, out / "runs", made_by)
    return report


def keep_records(runs: Iterable[RunResult], folder: Path, made_by: dict) -> list[str]:
    """Write the record of every included run into ``folder``, one sub-folder per run.

    Args:
        runs: the report's runs; left-out ones are skipped.
        folder: where the records go (created).
        made_by: the report's provenance, taken before it wrote anything.

    Returns:
        The records' folders, relative to ``folder``'s parent.
    """
    written, names = [], set()
    for run in runs:
        if not run.included:
            continue
        name, n = run.path.name, 1
        while name in names:  # two runs of the same name from different folders
            n += 1
            name = f"{run.path.name}-{n}"
        names.add(name)
        assert run.archive is not None  # every included run has its final archive
        record = Record(
            run.iteration,
            run.source,
            run.metrics,
            run.archive,
            run.notes,
            run.method,
            run.deployable,
            run.deployable_source,
        )
        write_record(run.path, record, folder / name, made_by)
        written.append(f"{folder.name}/{name}")
    return written


def _write_files(
    report: Report,
    heatmaps: Mapping[Path, str],
    curves: Mapping[str, list[tuple[str, str]]],
    profiles: Mapping[str, str],
    grids: Mapping[Path, HeatmapGrid],
) -> None:
    out, groups = report.out, report.groups
    table_md = report.main_table + "\n\n" + doc.markdown_table(*offset_table(groups)) + "\n"
    (out / "table.md").write_text(table_md if groups else "No run could be included.\n")
    records = table_records(groups)
    header = list(records[0]) if records else ["task", "method", "n"]
    write_csv(out / "table.csv", records, header)
    write_csv(out / "table_deployable.csv", table_records(groups, "deployable"), header)
    (out / "table_deployable.md").write_text(
        doc.markdown_table(*main_table(groups, "deployable")) + "\n" if groups else "\n"
    )
    tukey_header, tukey_rows = tukey_table(report.tukey)
    notes = [f"- {t}: {n}" for t, res in report.tukey.items() for n in res.notes]
    tukey_md = doc.markdown_table(tukey_header, tukey_rows) if tukey_rows else "No pair tested."
    if tukey_rows:
        offset_md = doc.markdown_table(*tukey_table(report.tukey_offset))
        tukey_md = f"Raw QD-Score:\n\n{tukey_md}\n\nOffset QD-Score:\n\n{offset_md}"
    (out / "tukey.md").write_text(tukey_md + "\n\n" + "\n".join(notes) + "\n")
    fields = ["task", "qd_score", "group1", "group2", "n1", "n2", "mean1", "mean2", "diff"]
    tukey_rows_csv = tukey_records(report.tukey) + tukey_records(report.tukey_offset, "offset")
    write_csv(out / "tukey.csv", tukey_rows_csv, [*fields, "sign", "pvalue", "significant"])
    ratio_fields = ["task", "archive", "qd_score", "ratio", "value", "low", "high", "bounded"]
    ratio_fields += ["n", "seeds_to_resolve"]
    write_csv(out / "ratios.csv", ratio_records(groups), ratio_fields)
    run_rows = run_records(report.runs)
    write_csv(out / "runs.csv", run_rows, list(run_rows[0]) if run_rows else ["path"])
    profile_fields = ["task", "method", "return_at_least", "cells_pct_mean", "cells_pct_std", "n"]
    write_csv(out / "profile.csv", profile_records(groups), profile_fields)
    blocks = build_document(report, heatmaps, curves, profiles, grids)
    (out / "report.md").write_text(doc.to_markdown(blocks))
    (out / "report.html").write_text(doc.to_html(blocks, "qdil report"))
    written = ["report.md", "report.html", "table.md", "table.csv", "tukey.md", "tukey.csv"]
    written += ["table_deployable.md", "table_deployable.csv", "ratios.csv"]
    written += ["runs.csv", "profile.csv", *heatmaps.values(), *profiles.values()]
    written += [path for images in curves.values() for _, path in images]
    videos = [v for vs in report.gallery.videos.values() for v in vs]
    written += [video.path.relative_to(out).as_posix() for video in videos]
    report.files = written
