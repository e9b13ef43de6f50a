"""``qdil render``: watch an elite's gait, one deterministic episode as an MP4 or a GIF."""

from __future__ import annotations

import argparse
from typing import Any

from qdil.cli.args import add_elite_choice, at_least, existing_run_dir


def even_size(text: str) -> int:
    """An argparse type: an even frame size of at least 16 pixels (H.264 needs even sizes)."""
    value = at_least(16)(text)
    if value % 2:
        raise argparse.ArgumentTypeError(f"must be even (H.264 video), got {value}")
    return value


def positive(text: str) -> float:
    """An argparse type: a positive number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {text}")
    return value


positive.__name__ = "float"
even_size.__name__ = "int"


def render_parser() -> argparse.ArgumentParser:
    """The options of ``qdil render``."""
    parser = argparse.ArgumentParser(
        prog="qdil render",
        description="Replay elites of a run's archive for one deterministic episode each "
        "(mean actions, the elite's own observation statistics, as qdil eval scores them) "
        "and draw it with MuJoCo's renderer from a camera that follows the torso. Each frame "
        "shows the return so far, the step, the foot contacts and the cell's measures. "
        "Needs headless OpenGL: EGL (Debian: libegl1 libgl1-mesa-dri) or OSMesa "
        "(libosmesa6); MUJOCO_GL picks one, else EGL then OSMesa are tried.",
    )
    parser.add_argument("run_dir", metavar="RUN_DIR", help="a run directory made by qdil fit")
    add_elite_choice(parser, ", one file each in the --out folder")
    parser.add_argument(
        "--out",
        metavar="PATH",
        help="a .mp4 or .gif file, or a folder for files named ARCHIVE_cell_I_J.FORMAT "
        "(default: RUN_DIR/videos)",
    )
    parser.add_argument(
        "--format",
        choices=("mp4", "gif"),
        default="mp4",
        help="format of the files written into a folder (default: mp4)",
    )
    parser.add_argument("--width", type=even_size, default=480, help="frame width (default 480)")
    parser.add_argument("--height", type=even_size, default=320, help="frame height (default 320)")
    parser.add_argument(
        "--max-steps",
        type=at_least(1),
        default=None,
        help="episode horizon (default: the run's env.max_episode_steps)",
    )
    parser.add_argument("--seed", type=at_least(0), default=0, help="reset seed (default 0)")
    parser.add_argument(
        "--fps",
        type=positive,
        default=30.0,
        help="frame rate to aim at; the video plays in real time, one frame every "
        "round(1 / (dt * FPS)) env steps (default 30: Walker2d every 4th step, 31.25 frames/s)",
    )
    parser.add_argument(
        "--high-quality",
        action="store_true",
        help="shadows, floor reflection and anti-aliasing (about 10 times slower with "
        "software OpenGL)",
    )
    return parser


def render(argv: list[str]) -> None:
    """``qdil render``: videos of elites of a run's archive."""
    parser = render_parser()
    args = parser.parse_args(argv)
    run_dir = existing_run_dir(parser, args.run_dir)
    from qdil.envs.gl import use_gl_backend
    from qdil.evaluation.video import render_elites

    options: dict[str, Any] = {
        "which": args.archive,
        "cell": args.cell,
        "top": args.top,
        "fmt": args.format,
        "width": args.width,
        "height": args.height,
        "max_steps": args.max_steps,
        "seed": args.seed,
        "fps": args.fps,
        "high_quality": args.high_quality,
    }
    videos = render_elites(run_dir, args.out, **options)  # bad input fails before OpenGL
    backend = use_gl_backend()  # the backend render_elites chose (cached)
    if args.top is not None and len(videos) < args.top:
        print(f"the {args.archive} archive holds {len(videos)} elites: rendered them all")
    frames = sum(video.frames for video in videos)
    seconds = sum(video.seconds for video in videos)
    drawing = sum(video.draw_seconds for video in videos)
    for video in videos:
        measures = ", ".join(f"{m:.2f}" for m in video.measures)
        print(
            f"cell {video.cell}: {video.steps} steps, return {video.episode_return:.2f}, "
            f"measures ({measures}), {video.frames} frames -> {video.path}"
        )
    print(
        f"rendered {frames} frames at {frames / drawing:.1f} frames/s "
        f"({args.width}x{args.height}, MUJOCO_GL={backend}); {seconds:.1f} s in all with "
        "the replay and writing"
    )
