"""``qdil sweep``: every recipe × seed as a run, on Ray Tune, then re-scored and reported."""

from __future__ import annotations

import argparse
import hashlib
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from qdil.sweeps.search import Search

SWEEP_EPILOG = """Any other --section.key VALUE is a recipe override applied to every trial
(as qdil fit takes it), e.g. --qd.iterations 50. Each trial is a run directory under --root
named as qdil fit names it (runs/walker_mcwae-seed0), with a short hash of the options that
change what it computes (runs/walker_mcwae-1a2b3c4d-seed0). Every trial is checked before
anything starts. Running the same command again continues every unfinished run from its
checkpoint and skips finished ones. Ray starts on this machine unless --address (or
RAY_ADDRESS) names a cluster.

qdil sweep SPEC.yaml runs a sweep spec: stages of recipes x seeds x a grid of options, run
in order (sweeps/evidence.yaml, sweeps/paper.yaml). --search optuna with --space ranges
tunes one recipe's options for a re-scored metric. Both: docs/guides/sweeps.md."""


def sweep_parser() -> argparse.ArgumentParser:
    """The options of ``qdil sweep`` (recipe overrides are parsed apart)."""
    parser = argparse.ArgumentParser(
        prog="qdil sweep",
        description="Run every recipe × seed as a trial on Ray Tune, re-score each finished "
        "run (as qdil eval) and, with --report, write one report over them.",
        epilog=SWEEP_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "recipes", nargs="+", type=Path, metavar="RECIPE",
        help="recipe files, or one sweep spec (a YAML file of stages: docs/guides/sweeps.md)",
    )  # fmt: skip
    parser.add_argument("--seeds", nargs="+", type=int, help="seeds of each recipe")
    parser.add_argument(
        "--cpus-per-trial", type=int, help="CPUs (physics and torch threads) per trial (default 1)"
    )
    parser.add_argument(
        "--gpus-per-trial", type=float, help="GPUs per trial (0.5: two per GPU; default 0)"
    )
    parser.add_argument("--address", help="a Ray cluster's address (default: this machine)")
    parser.add_argument(
        "--concurrent", type=int, default=0, help="trials at once at most (0: as the CPUs and "
        "GPUs allow; a trial whose Ray executor asks the cluster for more CPUs needs a cap)",
    )  # fmt: skip
    parser.add_argument(
        "--episodes", type=int, help="re-scoring episodes per elite (0: none; default 5)"
    )
    parser.add_argument("--report", type=Path, help="write one qdil report over the runs here")
    parser.add_argument("--root", type=Path, help="the runs folder (default runs)")
    parser.add_argument("--name", help="the sweep's name (default: from its trials)")
    parser.add_argument(
        "--stages", nargs="+", metavar="STAGE", help="a spec's stages to run (default: all)"
    )
    search = parser.add_argument_group(
        "search", "tune recipe options with Optuna (one recipe, one seed); rerun to go on"
    )
    search.add_argument("--search", choices=("optuna",), help="search the --space options")
    search.add_argument(
        "--space",
        action="append",
        default=[],
        metavar="KEY=RANGE",
        help="an option and its range: KEY=LOW:HIGH, KEY=log:LOW:HIGH, KEY=int:LOW:HIGH or "
        "KEY=choice:A,B,C (repeat for more)",
    )
    search.add_argument(
        "--metric", default="coverage", help="what ranks trials: a re-scored archive's "
        "qd_score, qd_score_offset, coverage, obj_max or obj_mean (default coverage)",
    )  # fmt: skip
    search.add_argument("--mode", default="max", choices=("max", "min"))
    search.add_argument("--samples", type=int, default=20, help="trials to run (default 20)")
    search.add_argument(
        "--grace", type=int, default=10, help="iterations before a poor trial may be stopped "
        "early (ASHA; 0: never stop one)",
    )  # fmt: skip

    return parser


def split(argv: list[str], parser: argparse.ArgumentParser) -> tuple[list[str], list[str]]:
    """``argv`` as the sweep's own arguments and the recipe overrides."""
    own = {s for action in parser._actions for s in action.option_strings}
    mine, overrides, i = [], [], 0
    while i < len(argv):
        arg = argv[i]
        if arg.split("=", 1)[0] in own:
            mine.append(arg)
            while "=" not in arg and i + 1 < len(argv) and not argv[i + 1].startswith("--"):
                i += 1
                mine.append(argv[i])
        elif arg.startswith("--"):
            overrides.append(arg)
            if "=" not in arg and i + 1 < len(argv):
                i += 1
                overrides.append(argv[i])
        else:
            mine.append(arg)
        i += 1
    return mine, overrides


def sweep(argv: list[str]) -> None:
    """``qdil sweep``: plan and check the trials, run them, report."""
    parser = sweep_parser()
    mine, rest = split(argv, parser)
    args = parser.parse_args(mine)
    from qdil.sweeps.spec import is_spec

    spec = len(args.recipes) == 1 and is_spec(args.recipes[0])
    if spec and args.seeds is not None:
        parser.error("a sweep spec gives each stage's seeds (seeds:); leave out --seeds")
    if not spec and (args.seeds is None or args.stages):
        parser.error("give --seeds of each recipe (or one sweep spec, whose --stages you may name)")
    given = {  # with a spec: these apply to every stage, over the spec's own
        key: value
        for key, value in (("cpus_per_trial", args.cpus_per_trial),
                           ("gpus_per_trial", args.gpus_per_trial), ("episodes", args.episodes),
                           ("concurrent", args.concurrent or None))
        if value is not None
    }  # fmt: skip
    args.cpus_per_trial = 1 if args.cpus_per_trial is None else args.cpus_per_trial
    args.gpus_per_trial = args.gpus_per_trial or 0.0
    args.episodes = 5 if args.episodes is None else args.episodes
    if args.cpus_per_trial < 1 or args.gpus_per_trial < 0 or args.episodes < 0:
        parser.error("--cpus-per-trial must be at least 1, --gpus-per-trial and --episodes >= 0")
    try:
        import ray.tune  # noqa: F401
    except ImportError as error:
        raise SystemExit(
            f"qdil sweep needs Ray Tune ({error}); install it with pip install 'qdil[sweep]' "
            "(or pip install 'ray[tune]')"
        ) from None
    from qdil.sweeps.driver import Resources, run_sweep
    from qdil.sweeps.trials import flat, parse_overrides, plan_trials

    overrides = parse_overrides(rest)
    if spec:
        return sweep_spec(args, overrides, given)
    args.root = args.root or Path("runs")
    what = [*(str(r.resolve()) for r in args.recipes), *map(str, args.seeds), *flat(overrides)]
    what += [*args.space, args.metric, args.mode] if args.search else []
    name = args.name or f"sweep-{hashlib.sha256(chr(10).join(what).encode()).hexdigest()[:8]}"
    if all(key != "logging.wandb_group" for key, _ in overrides):  # W&B shows them together
        overrides.append(("logging.wandb_group", name))
    trials = plan_trials(args.recipes, args.seeds, overrides, args.root)
    search = plan_search(args, trials, overrides) if args.search or args.space else None
    root = trials[0].root
    count = f"{search.samples} trials of a search" if search else f"{len(trials)} trials"
    print(f"qdil sweep {name}: {count} under {root}", file=sys.stderr)
    resources = Resources(args.cpus_per_trial, args.gpus_per_trial, args.address, args.concurrent)
    outcome = run_sweep(trials, resources, args.episodes, name, search)
    failed = outcome.failed
    if search is not None:
        show_ranking(outcome.ranked, search.metric, root / ".tune" / name / "ranking.csv")
    if args.report is not None:
        from qdil.evaluation.report import write_report

        runs = (
            [t.run_dir for t in trials]
            if search is None
            else [root / n for n, *_ in outcome.ranked]
        )
        write_report(runs, args.report)
        print(f"report: {args.report}", file=sys.stderr)
    end(failed, f"{len(failed)} of {len(trials)} trials failed (above); the same command "
        "continues them after a fix")  # fmt: skip


def sweep_spec(args: argparse.Namespace, overrides: list, given: dict) -> None:
    """``qdil sweep SPEC``: plan and check every stage, run them in order, report."""
    from qdil.sweeps.spec import load_spec, spec_name
    from qdil.sweeps.stages import run_spec

    name = args.name or spec_name(args.recipes[0])
    if all(key != "logging.wandb_group" for key, _ in overrides):  # W&B shows them together
        overrides.append(("logging.wandb_group", name))
    spec = load_spec(args.recipes[0], overrides, args.root, name, given, args.stages)
    count = sum(len(stage.trials) for stage in spec.stages)
    print(f"qdil sweep {spec.name}: {len(spec.stages)} stages, {count} trials", file=sys.stderr)
    failed = run_spec(spec, args.address, args.report)
    end(failed, f"{len(failed)} trials failed (above); the same command continues the sweep "
        "after a fix")  # fmt: skip


def end(failed: dict[str, str], summary: str) -> None:
    """Print each failed trial's error; exit non-zero with ``summary`` if any failed."""
    for trial_name, error in failed.items():
        print(f"FAILED {trial_name}: {error}", file=sys.stderr)
    if failed:
        raise SystemExit(f"qdil sweep: {summary}")


def plan_search(args: argparse.Namespace, trials: list, overrides: list) -> Search:
    """The search of ``args``, each option's range checked at its ends before anything runs.

    Raises:
        SystemExit: more than one trial to search from, no re-scoring, a bad range, or a
            range end that the recipe refuses (naming the key).
    """
    from qdil.sweeps.search import Search, parse_domain
    from qdil.sweeps.trials import plan_trial

    if not args.search or len(trials) != 1 or args.episodes < 1:
        raise SystemExit(
            "qdil sweep: a search takes --search optuna with --space ranges, one recipe, one "
            "seed and --episodes of 1 or more (it ranks trials by their re-scored archives)"
        )
    try:
        import optuna  # noqa: F401
    except ImportError as error:
        raise SystemExit(
            f"qdil sweep --search optuna needs Optuna ({error}); install it with "
            "pip install 'qdil[sweep]' (or pip install optuna)"
        ) from None
    space = tuple(parse_domain(spec) for spec in args.space)
    trial = trials[0]
    for domain in space:
        for end in domain.ends():
            plan_trial(trial.recipe, trial.seed, [*overrides, (domain.key, end)], trial.root)
    _, resolved = plan_trial(trial.recipe, trial.seed, overrides, trial.root)
    iterations = resolved["qd"]["iterations"]
    return Search(
        space, args.metric, args.mode, args.samples, args.grace, args.concurrent, iterations
    )


def show_ranking(ranked: list, metric: str, path: Path) -> None:
    """Print a search's re-scored trials, best first, with their options; keep them at ``path``.

    The CSV has one row per trial: ``run``, the metric (re-scored), then each option.
    """
    import csv

    from qdil.sweeps.search import text
    from qdil.sweeps.trials import flat

    print(f"re-scored trials by {metric}, best first (also {path}):", file=sys.stderr)
    keys = sorted({key for *_, options in ranked for key in options})
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["run", metric, *keys])
        for name, value, options in ranked:
            writer.writerow([name, repr(value), *(text(options.get(key, "")) for key in keys)])
            shown = " ".join(flat([(k, text(v)) for k, v in options.items()]))
            print(f"  {value:.6g}  {name}  {shown}", file=sys.stderr)
