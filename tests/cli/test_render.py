"""``qdil render`` through the real command line: videos of a tiny run's elites.

One smoke run (one QD iteration) is rendered for 30 steps at 96×64. The videos must hold
the documented frames (the reset state, one every stride steps, the last state), change over
time, read back as MP4 and GIF, and leave the episode's return as it is without rendering.
Tests that draw skip, naming the reason, where no OpenGL backend renders (CI without GL).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import pytest

from tests.commands import cli

ROOT = Path(__file__).resolve().parents[2]
STEPS = 30
SMALL = ["--width", "96", "--height", "64", "--max-steps", str(STEPS)]


@pytest.fixture(scope="module")
def run_dir(smoke_run: Path) -> Path:
    """A one-iteration Walker2d smoke run with a checkpoint (conftest's)."""
    return smoke_run


def frames_of(path: Path) -> np.ndarray:
    """(T, H, W, 3) frames of a video file, read back with imageio."""
    return np.stack([frame[..., :3] for frame in imageio.mimread(path, memtest=False)])


def elites(run_dir: Path):
    from qdil.qd.checkpoint import load_archive

    archive, _ = load_archive(run_dir, "true")
    return archive, archive.data()


def test_the_best_elites_mp4_has_one_frame_per_step_and_moves(
    run_dir: Path, gl: str, tmp_path: Path, capsys
) -> None:
    """At 125 frames/s (Walker2d's 8 ms step) every state is a frame: steps + 1 of them."""
    out = tmp_path / "best.mp4"
    code, stdout, err = cli(
        ["render", str(run_dir), "--out", str(out), "--fps", "125", *SMALL], capsys
    )
    assert code == 0, err
    frames = frames_of(out)
    archive, data = elites(run_dir)
    best = archive.int_to_grid_index(data["index"][[np.argmax(data["objective"])]])[0]
    assert f"cell {tuple(int(i) for i in best)}: {STEPS} steps" in stdout
    assert frames.shape == (STEPS + 1, 64, 96, 3)
    assert len({frame.tobytes() for frame in frames}) > STEPS // 2, "frames barely change"
    assert np.abs(frames[0].astype(int) - frames[-1].astype(int)).mean() > 1
    assert "frames/s" in stdout and str(out) in stdout


def test_the_gif_reads_back_with_a_frame_every_stride_steps_and_the_last(
    run_dir: Path, gl: str, tmp_path: Path
) -> None:
    """At 30 frames/s Walker2d is drawn every 4th step: 30 // 4 + 1, and the last state."""
    from qdil.evaluation.video import render_elites

    (video,) = render_elites(run_dir, tmp_path / "best.gif", width=96, height=64, max_steps=STEPS)
    frames = frames_of(video.path)
    assert video.frames == STEPS // 4 + 2 == len(frames)
    assert frames.shape[1:] == (64, 96, 3)
    assert len({frame.tobytes() for frame in frames}) > 1


def test_rendering_leaves_the_episodes_return_as_it_is(run_dir: Path, gl: str, tmp_path: Path):
    """The return drawn equals that of qdil eval's replay of the same elite and seed."""
    from qdil.envs.faces import torch_face
    from qdil.evaluation.rescore import ReplaySettings, elite_policies
    from qdil.evaluation.video import render_elites
    from qdil.rl.episodes import evaluate_policies

    _, data = elites(run_dir)
    row = int(np.argmax(data["objective"]))
    (video,) = render_elites(
        run_dir, tmp_path, fmt="gif", width=96, height=64, max_steps=STEPS, seed=3
    )
    settings = ReplaySettings.of_run(run_dir)
    env = settings.make_env(1, num_threads=1, max_episode_steps=STEPS)
    actor, stats = elite_policies(data, np.array([row]), env, settings.actor_hidden)
    face = torch_face(env)
    plain = evaluate_policies(face, actor, stats, 1, 3, None, True, settings.obs_clip)
    assert video.episode_return == plain.true_objective[0]
    assert video.steps == plain.lengths[0]
    np.testing.assert_array_equal(video.measures, plain.measures[0])
    assert video.path == tmp_path / f"true_cell_{'_'.join(map(str, video.cell))}.gif"


def test_top_2_writes_one_file_per_elite(run_dir: Path, gl: str, tmp_path: Path, capsys) -> None:
    out = tmp_path / "videos"
    args = ["render", str(run_dir), "--top", "2", "--out", str(out), "--format", "gif"]
    code, _, err = cli([*args, "--width", "96", "--height", "64", "--max-steps", "10"], capsys)
    assert code == 0, err
    files = sorted(out.iterdir())
    assert len(files) == 2, files
    assert all(f.name.startswith("true_cell_") and f.suffix == ".gif" for f in files)
    assert all(len(frames_of(f)) >= 2 for f in files)


def test_one_cell_of_the_deployable_archive(run_dir: Path, gl: str, tmp_path: Path, capsys):
    from qdil.qd.checkpoint import load_archive

    archive, _ = load_archive(run_dir, "deployable")
    data = archive.data()
    cell = tuple(int(i) for i in archive.int_to_grid_index(data["index"][[-1]])[0])
    out = tmp_path / "one.gif"
    args = ["render", str(run_dir), "--archive", "deployable", "--cell", *map(str, cell)]
    code, stdout, err = cli([*args, "--out", str(out), "--width", "64", "--height", "48"], capsys)
    assert code == 0, err
    assert f"cell {cell}:" in stdout
    assert frames_of(out).shape[1:] == (48, 64, 3)


def test_an_empty_cell_is_an_error_naming_the_occupied_ones(run_dir: Path, capsys) -> None:
    archive, data = elites(run_dir)
    occupied = {tuple(c) for c in archive.int_to_grid_index(data["index"])}
    empty = next((i, j) for i in range(10) for j in range(10) if (i, j) not in occupied)
    code, _, err = cli(["render", str(run_dir), "--cell", *map(str, empty)], capsys)
    assert code == 1
    assert f"cell {empty} is empty; occupied cells, best first:" in err
    assert "Traceback" not in err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--cell", "10", "0"], "--cell 10 0 is not a cell of the 10×10 grid"),
        (["--cell", "3"], "give 2 indices, one per measure, in 0 to 9, 0 to 9"),
        (["--out", "gait.avi"], "unknown video suffix '.avi'; give a .mp4 or .gif file"),
        (["--top", "2", "--out", "two.mp4"], "2 videos need a folder, not a file"),
        (["--width", "97"], "--width: must be even (H.264 video), got 97"),
        (["--cell", "1", "1", "--best"], "not allowed with argument --cell"),
    ],
    ids=["cell out of range", "cell of one index", "suffix", "top to a file", "odd", "both"],
)
def test_bad_input_is_a_clear_error(run_dir: Path, args: list[str], message: str, capsys):
    code, _, err = cli(["render", str(run_dir), *args], capsys)
    assert code in (1, 2)
    assert message in err
    assert "Traceback" not in err


def test_a_run_without_a_checkpoint_says_how_to_get_one(
    run_dir: Path, tmp_path: Path, capsys
) -> None:
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(run_dir / "config.yaml", bare / "config.yaml")
    code, _, err = cli(["render", str(bare)], capsys)
    assert code == 1
    assert "no checkpoint" in err and f"qdil fit --resume {bare}" in err


def test_no_opengl_is_one_line_naming_the_debian_packages(monkeypatch) -> None:
    from qdil.envs import gl

    monkeypatch.delenv("MUJOCO_GL", raising=False)
    monkeypatch.delenv("PYOPENGL_PLATFORM", raising=False)
    monkeypatch.setattr(gl, "probe", lambda backend: f"{backend} libraries not found")
    gl.use_gl_backend.cache_clear()
    try:
        with pytest.raises(gl.GLUnavailableError) as error:
            gl.use_gl_backend()
    finally:
        gl.use_gl_backend.cache_clear()
    message = str(error.value)
    assert "\n" not in message
    assert "MUJOCO_GL=egl: egl libraries not found" in message
    assert "MUJOCO_GL=osmesa" in message
    assert "libegl1 libgl1-mesa-dri (egl)" in message and "libosmesa6 (osmesa)" in message
