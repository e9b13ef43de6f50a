"""Running a spec's stages in order: each on Ray Tune, then its demonstrations and report.

A stage starts once every trial of the stages before it has finished; a stage with a failed
trial ends the sweep after its other trials (the same command continues it after a fix).
"""

from __future__ import annotations

import sys
from pathlib import Path

from qdil.sweeps.driver import Resources, ray_session, run_sweep
from qdil.sweeps.spec import Spec, Stage


def run_spec(spec: Spec, address: str | None, report: Path | None = None) -> dict[str, str]:
    """Run every stage of ``spec``; returns the failed trials' errors (empty: all finished).

    Args:
        spec: the planned spec (:func:`qdil.sweeps.spec.load_spec`).
        address: a Ray cluster's address (None: this machine, or ``RAY_ADDRESS``).
        report: a report over all the spec's trials, written here (None: the spec's own).
    """
    with ray_session(address):  # one Ray for every stage
        failed = _run_stages(spec, address)
    if failed:
        return failed
    out = report or spec.report
    if out is not None:
        _report([t for stage in spec.stages for t in stage.trials], out)
    return {}


def _run_stages(spec: Spec, address: str | None) -> dict[str, str]:
    """Each stage in order, its demonstrations and report after it; the first failed trials."""
    for number, stage in enumerate(spec.stages, 1):
        print(
            f"qdil sweep {spec.name}: stage {number} of {len(spec.stages)}, {stage.name}: "
            f"{len(stage.trials)} trials",
            file=sys.stderr,
        )
        resources = Resources(stage.cpus, stage.gpus, address, stage.concurrent)
        outcome = run_sweep(stage.trials, resources, stage.episodes, f"{spec.name}-{stage.name}")
        if outcome.failed:
            later = [s.name for s in spec.stages[number:]]
            if later:
                print(f"not started, after a failed stage: {', '.join(later)}", file=sys.stderr)
            return outcome.failed
        if stage.demos:
            make_demos(stage)
        if stage.report is not None:
            _report(stage.trials, stage.report)
    return {}


def make_demos(stage: Stage) -> None:
    """``qdil demos`` from the stage's one trial, unless its file is already written."""
    import subprocess

    options = dict(stage.demos)
    out = Path(options.pop("out"))
    if out.is_file():
        return
    (trial,) = stage.trials
    args = [f"--{key}={value}" for key, value in options.items()]
    print(f"qdil demos {trial.run_dir} --out {out} {' '.join(args)}", file=sys.stderr)
    command = [sys.executable, "-m", "qdil.cli", "demos", str(trial.run_dir), "--out", str(out)]
    if subprocess.run([*command, *args], check=False).returncode:
        raise SystemExit(
            f"qdil sweep: stage {stage.name}: qdil demos failed (above); the stages after it "
            "did not start; the same command continues the sweep after a fix"
        )


def _report(trials: list, out: Path) -> None:
    from qdil.evaluation.report import write_report

    write_report([t.run_dir for t in trials], out)
    print(f"report: {out}", file=sys.stderr)
