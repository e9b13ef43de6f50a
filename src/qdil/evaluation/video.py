"""Videos of elites: one deterministic episode per elite, drawn by MuJoCo's renderer.

An elite is replayed as ``qdil eval`` replays it (:mod:`qdil.evaluation.rescore`); every
``stride``-th state is copied into an ``MjData`` of a copy of the model and drawn from a
camera that tracks the torso, so drawing changes nothing in the simulation. Pillow adds the
return so far, the step, the foot contacts and the cell's measures. A video holds the reset
state, one frame every ``stride`` env steps and the last state: ``steps // stride + 1``
frames, one more when ``stride`` does not divide ``steps``. Software OpenGL is slow, so
shadows, reflections and anti-aliasing wait for ``high_quality`` (docs/guides/videos.md).
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from qdil.envs.faces import HostFace
from qdil.envs.gl import use_gl_backend
from qdil.envs.rendering import CAMERA_DISTANCE
from qdil.envs.vector import LocomotionVectorEnv
from qdil.evaluation.elites import select_rows
from qdil.evaluation.rescore import ReplaySettings, elite_policies
from qdil.evaluation.video_files import FORMATS, VideoWriter, video_paths
from qdil.qd.checkpoint import load_archive
from qdil.rl.episodes import EpisodePlayer
from qdil.rl.sampler import PolicySampler

_ON, _OFF = (80, 220, 100), (90, 90, 90)  # foot marker colours: touching, in the air


@dataclass(frozen=True)
class Video:
    """One rendered episode.

    Attributes:
        path: the video file.
        cell: the elite's grid cell.
        frames: frames written.
        steps: env steps of the episode.
        episode_return: the episode's true return.
        measures: (k,) the episode's measures (mean foot contacts).
        seconds: wall time of replaying, drawing and writing.
        draw_seconds: of which drawing the frames (MuJoCo's renderer and the overlay).
    """

    path: Path
    cell: tuple[int, ...]
    frames: int
    steps: int
    episode_return: float
    measures: np.ndarray
    seconds: float
    draw_seconds: float


class FrameRenderer:
    """Draws states of a task's model from a torso-tracking camera, with an overlay.

    Args:
        env: the task (its model is copied; the copy's ``MjData`` is the only one written).
        width: frame width in pixels.
        height: frame height in pixels.
        high_quality: shadows, the floor's reflection and 4× anti-aliasing.

    Attributes:
        seconds: wall time spent in :meth:`draw` so far.
    """

    def __init__(
        self, env: LocomotionVectorEnv, width: int, height: int, high_quality: bool = False
    ) -> None:
        self.model = copy.copy(env.model)
        visual = self.model.vis
        visual.global_.offwidth = max(visual.global_.offwidth, width)
        visual.global_.offheight = max(visual.global_.offheight, height)
        visual.quality.offsamples = 4 if high_quality else 0
        self.data = mujoco.MjData(self.model)
        self.renderer = mujoco.Renderer(self.model, height, width)
        for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION):
            self.renderer.scene.flags[flag] = high_quality
        self.camera = mujoco.MjvCamera()
        mujoco.mjv_defaultFreeCamera(self.model, self.camera)
        torso = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "torso")
        self.camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
        self.camera.trackbodyid = torso if torso >= 0 else 1
        task = env.task.reference_id or env.task.gym_id
        self.camera.distance = CAMERA_DISTANCE.get(task, 4.0)
        self.camera.elevation = -20.0
        self.camera.azimuth = 90.0  # side view: planar robots move along x
        self.font = ImageFont.load_default(size=max(8, height // 22))
        self.feet = [name.removesuffix("_geom") for name in env.task.feet]
        self.seconds = 0.0

    def draw(
        self, qpos: np.ndarray, qvel: np.ndarray, lines: list[str], contacts: np.ndarray
    ) -> np.ndarray:
        """One frame of a state.

        Args:
            qpos: (nq,) positions.
            qvel: (nv,) velocities.
            lines: text for the top left corner.
            contacts: (k,) 0/1 foot contacts, drawn as markers at the bottom left.

        Returns:
            (height, width, 3) uint8 RGB frame.
        """
        start = time.perf_counter()
        self.data.qpos[:], self.data.qvel[:] = qpos, qvel
        mujoco.mj_forward(self.model, self.data)
        self.renderer.update_scene(self.data, camera=self.camera)
        image = Image.fromarray(self.renderer.render())
        draw = ImageDraw.Draw(image, "RGBA")
        size = self.font.size
        pad = max(2, size // 4)
        width = max(int(draw.textlength(line, font=self.font)) for line in lines)
        draw.rectangle((0, 0, width + 2 * pad, len(lines) * (size + pad) + pad), (0, 0, 0, 140))
        for row, line in enumerate(lines):
            draw.text((pad, pad + row * (size + pad)), line, (255, 255, 255), font=self.font)
        x, y = pad, image.height - size - 2 * pad
        for name, touching in zip(self.feet, contacts, strict=True):
            draw.ellipse((x, y, x + size, y + size), _ON if touching else _OFF, (0, 0, 0))
            x += size + pad
            draw.text((x, y), name, (255, 255, 255), font=self.font, stroke_width=1, stroke_fill=0)
            x += int(draw.textlength(name, font=self.font)) + 2 * pad
        self.seconds += time.perf_counter() - start
        return np.asarray(image)

    def close(self) -> None:
        """Free the renderer's OpenGL context."""
        self.renderer.close()


def play(
    env: LocomotionVectorEnv,
    sampler: PolicySampler,
    seed: int,
    stride: int,
    show: Callable[[int, float, np.ndarray], None],
) -> EpisodePlayer:
    """One deterministic episode on ``env``'s first slot, shown every ``stride`` steps.

    Args:
        env: a one-slot environment with autoreset disabled.
        sampler: the policy.
        seed: reset seed.
        stride: steps between two calls of ``show`` (the last state is always shown).
        show: called with the step, the return so far and the (k,) foot contacts while
            the environment holds that state: after the reset, then every ``stride`` steps.

    Returns:
        The player, holding the episode's return, length and measures.
    """
    player = EpisodePlayer(HostFace(env), 1, seed, record=False)  # drawn from host arrays
    so_far = 0.0
    show(0, so_far, player.contacts[0].numpy())
    while not player.finished:
        player.step(lambda obs: sampler.sample(obs, None, True, log_probs=False))
        so_far += float(player.last_rewards[0])
        if player.num_steps % stride == 0 or player.finished:
            show(player.num_steps, so_far, player.contacts[0].numpy())
    return player


def record(
    env: LocomotionVectorEnv,
    sampler: PolicySampler,
    painter: FrameRenderer,
    path: Path,
    title: str,
    seed: int,
    stride: int,
    cell: tuple[int, ...],
) -> Video:
    """Play one episode (:func:`play`) and write its frames to ``path``."""
    start, drawn = time.perf_counter(), painter.seconds
    writer = VideoWriter(path, 1 / (env.task.dt * stride))

    def show(steps: int, so_far: float, contacts: np.ndarray) -> None:
        lines = [title, f"step {steps}/{env.max_episode_steps}   return {so_far:.1f}"]
        qpos, qvel = env.physics.view("qpos")[0], env.physics.view("qvel")[0]
        writer.append(painter.draw(qpos, qvel, lines, contacts))

    player = play(env, sampler, seed, stride, show)
    writer.close()
    return Video(
        path=path,
        cell=cell,
        frames=writer.count,
        steps=player.num_steps,
        episode_return=float(player.returns[0]),
        measures=player.measures[0].numpy().copy(),
        seconds=time.perf_counter() - start,
        draw_seconds=painter.seconds - drawn,
    )


def render_elites(
    run_dir: str | Path,
    out: str | Path | None = None,
    *,
    which: str = "true",
    cell: list[int] | None = None,
    top: int | None = None,
    fmt: str = "mp4",
    width: int = 480,
    height: int = 320,
    max_steps: int | None = None,
    seed: int = 0,
    fps: float = 30.0,
    high_quality: bool = False,
) -> list[Video]:
    """Render one deterministic episode of each chosen elite of a run's archive.

    Args:
        run_dir: the run directory.
        out: a .mp4/.gif file, or a folder (default ``RUN_DIR/videos``).
        which: ``true`` (the paper's archive) or ``deployable``.
        cell: one grid cell (k indices); ``None`` and no ``top``: the best elite.
        top: this many elites spread over the measure space.
        fmt: format of files named in a folder, ``mp4`` or ``gif``.
        width: frame width in pixels.
        height: frame height in pixels.
        max_steps: horizon (``None``: the run's).
        seed: reset seed of every episode.
        fps: asked frame rate; frames are every ``round(1 / (dt · fps))`` env steps.
        high_quality: shadows, the floor's reflection and anti-aliasing (slow in software).

    Returns:
        The videos, in the order chosen (the best elite first).

    Raises:
        CheckpointError: the run has no checkpoint (or no deployable archive).
        ValueError: an unknown suffix, a bad or empty cell, an empty archive.
        GLUnavailableError: no OpenGL backend works here.
    """
    run_dir = Path(run_dir)
    out = run_dir / "videos" if out is None else Path(out)
    if fmt not in FORMATS:
        raise ValueError(f"format {fmt!r} is not one of {', '.join(FORMATS)}")
    video_paths(out, [()], which, fmt)  # a bad suffix fails before the archive is read
    archive, _ = load_archive(run_dir, which)
    elites = archive.data()
    rows = select_rows(archive, elites, cell, top)
    cells = [tuple(int(i) for i in c) for c in archive.int_to_grid_index(elites["index"][rows])]
    paths = video_paths(out, cells, which, fmt)
    options = {"max_steps": max_steps, "seed": seed, "fps": fps, "high_quality": high_quality}
    label = f"{which} archive"
    return render_rows(run_dir, elites, rows, cells, paths, label, width, height, **options)


def render_rows(
    run_dir: str | Path,
    elites: dict[str, np.ndarray],
    rows: np.ndarray,
    cells: list[tuple[int, ...]],
    paths: list[Path],
    label: str,
    width: int = 480,
    height: int = 320,
    *,
    max_steps: int | None = None,
    seed: int = 0,
    fps: float = 30.0,
    high_quality: bool = False,
) -> list[Video]:
    """Render one deterministic episode of each of ``rows`` of an archive's elites.

    The replay of :func:`render_elites`, for a caller that holds the archive already
    (``qdil report`` renders from the corrected archive of ``qdil eval`` where there is one).

    Args:
        run_dir: the run directory (its recipe gives the task and the policy's shape).
        elites: pyribs archive data with ``index``, ``solution``, ``measures`` and the
            observation statistics ``obs_mean``, ``obs_var``, ``obs_count``.
        rows: (n,) rows of ``elites`` to render.
        cells: their n grid cells.
        paths: n video files (.mp4 or .gif).
        label: which archive, for the title drawn on the frames.
        width: frame width in pixels.
        height: frame height in pixels.
        max_steps: horizon (``None``: the run's).
        seed: reset seed of every episode.
        fps: asked frame rate; frames are every ``round(1 / (dt · fps))`` env steps.
        high_quality: shadows, the floor's reflection and anti-aliasing.

    Returns:
        The videos, in the order of ``rows``.

    Raises:
        GLUnavailableError: no OpenGL backend works here.
    """
    use_gl_backend()
    settings = ReplaySettings.of_run(run_dir)
    env = settings.make_env(1, num_threads=1, max_episode_steps=max_steps)
    stride = max(1, round(1 / (env.task.dt * fps)))
    painter = FrameRenderer(env, width, height, high_quality)
    videos = []
    try:
        for row, cell, path in zip(rows, cells, paths, strict=True):
            actor, stats = elite_policies(elites, np.array([row]), env, settings.actor_hidden)
            sampler = PolicySampler(actor, stats, settings.obs_clip)
            measures = " ".join(f"{m:.2f}" for m in elites["measures"][row])
            title = f"{settings.task} {label}, cell {cell}: measures {measures}"
            videos.append(record(env, sampler, painter, path, title, seed, stride, cell))
    finally:
        painter.close()
    return videos
