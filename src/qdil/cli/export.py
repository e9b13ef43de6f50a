"""``qdil export``: elites of a run as standalone policy files, each with a JSON beside it."""

from __future__ import annotations

import argparse

from qdil.cli.args import add_elite_choice, at_least, existing_run_dir


def export_parser() -> argparse.ArgumentParser:
    """The options of ``qdil export``."""
    parser = argparse.ArgumentParser(
        prog="qdil export",
        description="Write elites of a run's archive as standalone policy files that run "
        "without qdil: each holds the elite's observation normalisation, its network and the "
        "deterministic action in the task's bounds (input obs: (B, obs_dim) float32; output "
        "action: (B, A) float32). Beside each, a JSON with the task, cell, measures, the "
        "return of deterministic scoring episodes played on export (reset seed, length, "
        "return of each), the run and its commit. --format minari NAME writes the elites' "
        "rollouts as a local Minari dataset instead. Guide: docs/guides/use-a-gait-outside-qdil.md",
    )
    parser.add_argument("run_dir", metavar="RUN_DIR", help="a run directory made by qdil fit")
    parser.add_argument(
        "dataset",
        nargs="?",
        metavar="NAME",
        help="--format minari: the dataset's Minari id, e.g. qdil/walker2d/gaits-v0 (written "
        "under MINARI_DATASETS_PATH, default ~/.minari/datasets)",
    )
    add_elite_choice(parser)
    parser.add_argument(
        "--format",
        choices=("onnx", "torch", "minari"),
        default="onnx",
        help="onnx: an ONNX model, opset 18 (onnxruntime runs it); torch: a torch.export "
        "program (.pt2, torch.export.load); minari: the elites' rollouts as a Minari dataset "
        "NAME; default onnx",
    )
    parser.add_argument("--out", metavar="DIR", help="folder for the policy files")
    parser.add_argument(
        "--episodes",
        type=at_least(1),
        default=None,
        help="deterministic episodes per elite: scoring episodes recorded in its JSON "
        "(default 5), or episodes in the dataset (--format minari, default 1)",
    )
    parser.add_argument(
        "--seed", type=at_least(0), default=0, help="reset seed of the first episode (default 0)"
    )
    return parser


def export(argv: list[str]) -> None:
    """``qdil export``: elites of a run as policy files."""
    parser = export_parser()
    args = parser.parse_intermixed_args(argv)  # NAME may follow --format minari
    if args.format == "minari":
        if args.dataset is None or args.out is not None:
            parser.error("--format minari takes a dataset NAME after RUN_DIR, not --out")
    elif args.out is None or args.dataset is not None:
        parser.error(f"--format {args.format} writes files into --out DIR (NAME is for minari)")
    run_dir = existing_run_dir(parser, args.run_dir)
    if args.format == "minari":
        from qdil.export.dataset import export_dataset

        dataset = export_dataset(
            run_dir,
            args.dataset,
            which=args.archive,
            cell=args.cell,
            top=args.top,
            episodes=args.episodes or 1,
            seed=args.seed,
        )
        import minari

        print(
            f"wrote Minari dataset {args.dataset}: {dataset.total_episodes} episodes, "
            f"{dataset.total_steps} steps -> {minari.storage.get_dataset_path(args.dataset)}"
        )
        return
    from qdil.export import export_policies

    written = export_policies(
        run_dir,
        args.out,
        args.format,
        which=args.archive,
        cell=args.cell,
        top=args.top,
        episodes=args.episodes or 5,
        seed=args.seed,
    )
    for item in written:
        meta = item.metadata
        measures = ", ".join(f"{m:.2f}" for m in meta["measures"])
        print(
            f"cell {tuple(meta['cell'])}: measures ({measures}), corrected return "
            f"{meta['corrected_return']:.1f} over {len(meta['episodes'])} episodes -> {item.path}"
        )
    if args.top is not None and len(written) < args.top:
        print(f"the {args.archive} archive holds {len(written)} elites: exported them all")
