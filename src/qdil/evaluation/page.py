"""The report page: :class:`Report` (what ``write_report`` made) and its document blocks.

:func:`build_document` lays out ``report.md`` / ``report.html``: the main and offset tables,
the sources of the metrics, the Tukey table, the return profiles of the final archives,
learning curves, heatmaps (clickable on the HTML page, :mod:`qdil.evaluation.explorer`),
the run list and the runs left out or unfinished.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from qdil.evaluation import document as doc
from qdil.evaluation import explorer
from qdil.evaluation.figures import HeatmapGrid, colour_range
from qdil.evaluation.gallery import Gallery, VideoSettings
from qdil.evaluation.profiles import profile_table
from qdil.evaluation.ratios import BOOTSTRAP_SEED, RESAMPLES
from qdil.evaluation.runs import (
    Groups,
    RunResult,
)
from qdil.evaluation.stats import (
    TukeyResult,
)
from qdil.evaluation.tables import (
    main_table,
    offset_table,
    ratio_records,
    ratio_table,
    tukey_table,
)


@dataclass
class Report:
    """What :func:`write_report` made.

    Attributes:
        out: the output folder.
        runs: every run found (included and left out).
        groups: included runs by task and method.
        tukey: Tukey HSD results of the raw QD-Score by task.
        main_table: the main table as Markdown.
        files: every file written, relative to ``out``.
        gallery: the videos of elites (none where none were asked for or could be made).
        tukey_offset: the same test of the offset QD-Score (positive where raw QD-Scores
            sum returns of either sign near zero).
    """

    out: Path
    runs: list[RunResult]
    groups: Groups
    tukey: dict[str, TukeyResult]
    main_table: str
    files: list[str]
    gallery: Gallery = field(default_factory=lambda: Gallery(VideoSettings(count=0)))
    tukey_offset: dict[str, TukeyResult] = field(default_factory=dict)


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
    report: Report,
    heatmaps: Mapping[Path, str],
    curves: Mapping[str, list[tuple[str, str]]],
    profiles: Mapping[str, str] | None = None,
    grids: Mapping[Path, HeatmapGrid] | None = None,
) -> list[doc.Block]:
    """The blocks of ``report.md`` / ``report.html``.

    Args:
        report: what :func:`~qdil.evaluation.report.write_report` collected.
        heatmaps: run directory -> heatmap PNG.
        curves: task -> ``(metric label, PNG)`` pairs of the learning curves.
        profiles: task -> return-profile PNG; ``None`` leaves the section out.
        grids: run directory -> where its heatmap PNG draws the cells: the HTML page's
            heatmaps are clickable (``None``: plain images).
    """
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
        doc.heading("Main results: the true-keyed archives (the paper's protocol)"),
        doc.text(
            "Each cell keeps the policy with the best true return among all the run proposed: "
            "the paper's reported archive. The imitation methods never see that reward, so "
            "this is an oracle's choice of elites."
        ),
    ]
    if groups:
        blocks += [doc.table(*main_table(groups))]
        blocks += [doc.text("n with `*`: the group includes unfinished runs (see below).")]
        blocks += [doc.heading("The deployable archives", 3)]
        blocks += [
            doc.text(
                "Each cell keeps the policy with the best return under the run's own "
                "objective (the learned reward, plus bonus): what a user without the true "
                "reward gets. Scored like the table above, on the true return, over the runs "
                "that have one (n counts them; a checkpoint made before the deployable archive "
                "existed has none); `–` where none has."
            )
        ]
        blocks += [doc.table(*main_table(groups, "deployable"))]
        blocks += [doc.heading("Offset QD-Score (PPGA convention)", 3)]
        blocks += [doc.table(*offset_table(groups))]
        blocks += [doc.heading("Sources of the final metrics", 3), doc.bullets(_sources(groups))]
    else:
        blocks += [doc.text("No run could be included.")]
    ratios = ratio_records(groups)
    if ratios:
        blocks += [doc.heading("Ratios to the expert and to GAIL")]
        blocks += [
            doc.text(
                "Ratio of the methods' mean QD-Scores over seeds (raw: the paper's sum of "
                "returns; offset: PPGA's, which stays positive), with a 95 % percentile "
                "bootstrap interval that resamples each method's seeds (crude with 3 seeds, "
                f"none with 1; {RESAMPLES:,} resamples, random state {BOOTSTRAP_SEED}, so that "
                "the report made again gives the same digits). Where the reference's mean "
                "QD-Score may be 0 (its own interval holds 0) the ratio has no bounded interval "
                "and says so. Seeds to resolve: seeds per method a two-sided t-test (α = 0.05, "
                "power 0.8) would need to find the observed gap, from the pooled spread."
            )
        ]
        blocks += [doc.table(*ratio_table(ratios))]
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
    header, rows = tukey_table(report.tukey_offset)
    if rows:
        blocks += [doc.heading("Tukey HSD test of the offset QD-Score", 3), doc.table(header, rows)]
    if profiles is not None and groups:
        blocks += _profile_blocks(groups, profiles)
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
    if grids is not None and groups:
        blocks += [doc.text(explorer.videos_text(report.gallery)), explorer.script_block()]
    for number, task in enumerate(groups):
        vmin, vmax = colour_range(r.archive for rs in groups[task].values() for r in rs)
        scale = "empty archives" if vmin is None else f"colour scale {vmin:.4g} to {vmax:.4g}"
        blocks += [doc.heading(task, 3), doc.text(f"Final archives; {scale} for every run.")]
        images = doc.table(*_image_rows(groups, task, heatmaps))
        if grids is None:
            blocks += [images]
            continue
        markdown = doc.to_markdown([images]).strip()
        blocks += explorer.task_blocks(
            number, groups[task], heatmaps, grids, report.gallery, report.out, markdown
        )
    blocks += [doc.heading("Runs"), doc.table(*_runs_table(runs))]
    blocks += [doc.heading("Runs left out / unfinished")]
    blocks += [
        doc.text("Also listed: included runs with remarks (stale `eval.json`, shared seeds).")
    ]
    problems = _problem_rows(runs)
    header = ["run", "status", "reason"]
    blocks += [doc.table(header, problems)] if problems else [doc.text("None.")]
    return blocks


def _profile_blocks(groups: Groups, profiles: Mapping[str, str]) -> list[doc.Block]:
    blocks = [doc.heading("Return profiles of the final archives")]
    blocks += [
        doc.text(
            "The percentage of all cells of the grid whose elite returns at least x, from the "
            "same archives as the main table: at the lowest return it is the coverage, and a "
            "method above another at high x holds more cells with good policies. Mean over "
            "seeds (± sample std); the table reads the curves at a quarter, half and three "
            "quarters of the task's best return."
        )
    ]
    for task in groups:
        blocks += [doc.heading(task, 3), doc.table(*profile_table(groups, task))]
        if task in profiles:
            blocks += [doc.image(profiles[task], f"{task} return profile")]
    return blocks


def _curve_row(images: Sequence[tuple[str, str]]) -> tuple[list[str], list[list[str]]]:
    return [label for label, _ in images], [[f"![{label}]({path})" for label, path in images]]


def _runs_table(runs: Sequence[RunResult]) -> tuple[list[str], list[list[str]]]:
    header = ["run", "task", "method", "seed", "iteration", "status", "source"]
    rows = [
        [
            f"`{run.path}`",
            run.task_label or "–",
            run.method or "–",
            "–" if run.seed is None else str(run.seed),
            f"{run.iteration if run.iteration is not None else '–'} / {run.target or '–'}",
            run.status,
            run.source or "–",
        ]
        for run in runs
    ]
    return header, rows
