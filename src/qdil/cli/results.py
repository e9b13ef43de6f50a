"""``qdil eval`` and ``qdil report``: corrected archives, tables, tests and figures."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from qdil.cli.args import at_least, existing_run_dir


def evaluate(argv: list[str]) -> None:
    """``qdil eval``: re-score a run's archive with deterministic episodes on the true reward."""
    parser = argparse.ArgumentParser(
        prog="qdil eval",
        description="Re-evaluate every elite of a run's two policy archives (the paper's "
        "true-keyed one and the deployable one, chosen by the run's own objective) with "
        "deterministic actions; writes corrected_archive.pkl, corrected_deployable.pkl and "
        "eval.json into the run directory.",
    )
    parser.add_argument("run_dir", metavar="RUN_DIR", help="a run directory made by qdil fit")
    parser.add_argument(
        "--episodes", type=at_least(1), default=5, help="episodes per elite (PPGA: 50)"
    )
    parser.add_argument("--batch", type=at_least(1), default=64, help="elites evaluated together")
    parser.add_argument("--seed", type=at_least(0), default=0, help="reset seed")
    parser.add_argument(
        "--num-threads", type=at_least(1), default=None, help="physics threads (default: all)"
    )
    args = parser.parse_args(argv)
    run_dir = existing_run_dir(parser, args.run_dir)
    from qdil.evaluation.rescore import rescore_archive

    _, summary = rescore_archive(
        run_dir, args.episodes, args.batch, args.seed, args.num_threads, progress=True
    )
    deployable = summary["deployable"] or {}
    columns = [("true-keyed (paper)", summary)]
    if deployable:
        columns.append(("deployable", deployable))
    for name, part in columns:
        print(
            f"{name}: {part['elites_evaluated']} elites x {args.episodes} deterministic "
            f"episodes ({part['env_steps']:,} env steps); QD-Score standard error over "
            f"episodes {part['qd_score_se']:.4g}"
        )
    header = " | ".join(f"{name}: training | {name}: corrected" for name, _ in columns)
    print(f"| metric | {header} |\n|---|{'---|---|' * len(columns)}")
    for key in ("qd_score", "qd_score_offset", "coverage", "obj_max", "obj_mean", "num_elites"):
        cells = " | ".join(
            f"{part['training_metrics'][key]:.6g} | {part['metrics'][key]:.6g}"
            for _, part in columns
        )
        print(f"| {key} | {cells} |")
    if not deployable:
        print("the checkpoint predates the deployable archive: only the true-keyed one is scored")


def report(argv: list[str]) -> None:
    """``qdil report``: the paper's tables, Tukey HSD tests, heatmaps and learning curves."""
    parser = argparse.ArgumentParser(
        prog="qdil report",
        description="Paper-style report of run directories: main table (mean ± std over "
        "seeds), Tukey HSD on the QD-Score, archive heatmaps, learning curves. Runs that are "
        "missing or unfinished are listed, not dropped. On report.html a click on a heatmap's "
        "cell shows its elite's return, measures and video; videos need headless OpenGL "
        "(see qdil render --help) and are left out, saying why, without it.",
    )
    parser.add_argument("paths", nargs="+", metavar="RUN_DIR", help="runs or folders of runs")
    parser.add_argument("--out", required=True, help="output folder of the report")
    parser.add_argument(
        "--label",
        action="append",
        default=[],
        metavar="RUN_DIR=LABEL",
        help="method label of one run (repeatable); default: reward model [+ -Bonus]",
    )
    parser.add_argument(
        "--reference",
        metavar="METHOD",
        help="Tukey table: only pairs with this method, as group2 (the paper's layout)",
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="write into OUT even where git tracks files in it (a report kept in the "
        "repository, such as docs/reports/...); without it such an OUT is refused",
    )
    parser.add_argument(
        "--no-records",
        action="store_true",
        help="do not keep records of the runs in OUT/runs/ (config, curves, final archive "
        "without policies: enough to make the report again when the runs are gone)",
    )
    parser.add_argument(
        "--videos",
        type=at_least(0),
        default=6,
        metavar="K",
        help="videos of K elites per run, spread over its archive, for report.html "
        "(default 6; 0: none). Each is one deterministic episode at 320x208, as qdil render "
        "draws it: seconds to a minute each with software OpenGL",
    )
    args = parser.parse_args(argv)
    labels = {}
    for item in args.label:
        path, sep, label = item.rpartition("=")
        if not sep or not path or not label:
            parser.error(f"--label takes RUN_DIR=LABEL, got {item!r}")
        labels[path] = label
    tracked = tracked_files(Path(args.out))
    if tracked and not args.force:
        raise SystemExit(
            f"qdil report: error: git tracks {len(tracked)} file(s) in {args.out} (e.g. "
            f"{tracked[0]}), which the report would overwrite; pass --force to update a "
            "report kept in the repository, or choose another --out"
        )
    from qdil.evaluation.gallery import VideoSettings
    from qdil.evaluation.report import write_report

    made = write_report(
        args.paths,
        args.out,
        labels=labels,
        reference=args.reference,
        records=not args.no_records,
        videos=VideoSettings(count=args.videos),
    )
    left_out = [run for run in made.runs if not run.included]
    unfinished = [run for run in made.runs if run.included and run.unfinished]
    print(made.main_table or "no run could be included")
    print(
        f"\n{len(made.runs) - len(left_out)} run(s) included ({len(unfinished)} unfinished), "
        f"{len(left_out)} left out"
    )
    for run in [run for run in made.runs if run.problems or run.notes]:
        print(f"  {run.path}: {run.status}: {'; '.join(run.problems + run.notes)}")
    gallery = made.gallery
    if gallery.count:
        print(f"videos: {gallery.count} in {gallery.seconds:.0f} s -> {Path(args.out) / 'videos'}")
    elif args.videos and gallery.reason:  # one line; the page says it too
        print(f"qdil report: no videos: {gallery.reason}", file=sys.stderr)
    for path, note in gallery.notes.items():
        print(f"  {path}: {note}", file=sys.stderr)
    print(f"report: {Path(args.out) / 'report.md'} (also report.html, tables, figures)")
    if len(left_out) < len(made.runs):  # at least one run made it into the report
        return
    raise SystemExit(
        "qdil report: error: no run could be included (reasons above); give run directories "
        "made by qdil fit, or folders holding them"
    )


def tracked_files(folder: Path) -> list[str]:
    """The files git tracks in ``folder``; none outside a git work tree or without git.

    Args:
        folder: a folder, which need not exist yet.
    """
    anchor = folder.resolve()
    while not anchor.is_dir():  # git runs in the nearest folder that exists
        anchor = anchor.parent
    try:
        listed = subprocess.run(
            ["git", "ls-files", "--full-name", "--", str(folder.resolve())],
            cwd=anchor,
            capture_output=True,
            text=True,
            timeout=60,
        )
    except (OSError, subprocess.TimeoutExpired):  # no git here: nothing to protect
        return []
    # outside a work tree git fails ("not a git repository"): no check either
    return listed.stdout.splitlines() if listed.returncode == 0 else []
