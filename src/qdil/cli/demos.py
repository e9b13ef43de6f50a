"""``qdil demos``: demonstrations from an expert run, a demo file's table, or an import."""

from __future__ import annotations

import argparse

from qdil.cli.args import at_least, existing_run_dir


def demos(argv: list[str]) -> None:
    """``qdil demos``: demonstrations from an expert run, their table, or an import."""
    parser = argparse.ArgumentParser(
        prog="qdil demos",
        description="Make demonstrations from a run's true-return archive (the paper's "
        "pipeline: top elites, farthest-point sampling in measure space, one deterministic "
        "episode each), print a demonstration file's table, or import outside data.",
    )
    parser.add_argument("run_dir", nargs="?", metavar="RUN_DIR", help="an expert run directory")
    parser.add_argument("--out", help="output .npz file")
    parser.add_argument("--top", type=at_least(1), default=500, help="candidate pool: best elites")
    parser.add_argument("--num", type=at_least(1), default=4, help="demonstrations to pick")
    parser.add_argument("--seed", type=at_least(0), default=0, help="reset seed of the episodes")
    parser.add_argument("--info", metavar="FILE", help="print the table of a demo file")
    parser.add_argument(
        "--import-npz",
        metavar="FILE",
        help="import D4RL-style arrays "
        "(observations, actions, next_observations, optional rewards, "
        "terminals, timeouts) from an .npz; contacts are replayed",
    )
    parser.add_argument("--import-minari", metavar="DATASET", help="import a local Minari dataset")
    parser.add_argument("--task", help="task of imported data, e.g. Walker2d-v5")
    args = parser.parse_args(argv)
    from qdil.demos.io import demo_table, episode_summary, load_demos, save_demos

    if args.info:
        loaded = load_demos(args.info)
        print(demo_table(loaded))
        print("\n".join(episode_summary(loaded)))
        provenance = loaded.metadata
        if "run" in provenance:
            print(
                f"from {provenance['run']} (iteration {provenance.get('run_iteration')}, "
                f"seed {provenance.get('run_seed')}), qdil {provenance.get('qdil_version')}"
            )
        return
    if not args.out:
        parser.error("--out is required to write demonstrations")
    if args.import_npz or args.import_minari:
        from qdil.demos.importing import import_minari, import_npz

        if args.import_minari:
            made = import_minari(args.import_minari, task=args.task)
        else:
            if not args.task:
                parser.error("--task is required with --import-npz")
            made = import_npz(args.import_npz, args.task)
        save_demos(made, args.out)
    else:
        if not args.run_dir:
            parser.error("give a run directory (or --info FILE / --import-npz FILE)")
        run_dir = existing_run_dir(parser, args.run_dir)
        from qdil.demos.generate import demos_from_run
        from qdil.qd.checkpoint import load_archive

        archive, iteration = load_archive(run_dir, "true")
        made, qpos, qvel = demos_from_run(
            run_dir, archive, iteration, top=args.top, num=args.num, seed=args.seed
        )
        save_demos(made, args.out, qpos, qvel)
    print(demo_table(made))
    print(f"wrote {args.out}")
