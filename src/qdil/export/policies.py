"""``qdil export``'s policy files: chosen elites, each as one file with a JSON beside it.

Each elite is played for a few deterministic episodes on qdil's C engine (equal to
gymnasium's task) when exported; the JSON records them (reset seed, length, return), so that
a user can check the file in their own loop against the numbers qdil measured.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from qdil.demos.generate import record_episodes
from qdil.evaluation.elites import select_rows
from qdil.evaluation.rescore import ReplaySettings
from qdil.export.formats import SUFFIXES, save_policy
from qdil.export.policy import GaitPolicy
from qdil.files import atomic_write
from qdil.provenance import PROVENANCE_JSON, git_state
from qdil.qd.checkpoint import load_archive
from qdil.rl.normalize import stats_from_fields


@dataclass(frozen=True)
class ExportedPolicy:
    """One elite written by :func:`export_policies`.

    Attributes:
        path: the policy file.
        metadata_path: the JSON beside it.
        metadata: what the JSON holds.
    """

    path: Path
    metadata_path: Path
    metadata: dict[str, Any]


def _training_commit(run_dir: Path) -> str | None:
    """The commit that trained the run (its provenance's last start), if recorded."""
    path = run_dir / PROVENANCE_JSON
    if not path.is_file():
        return None
    starts = json.loads(path.read_text())
    return starts[-1].get("commit") if isinstance(starts, list) and starts else None


def scoring_episodes(
    settings: ReplaySettings,
    solution: np.ndarray,
    fields: dict[str, np.ndarray],
    episodes: int,
    seed: int,
) -> list[dict[str, Any]]:
    """``episodes`` deterministic episodes of one elite, episode i reset with ``seed + i``.

    Returns:
        ``{"seed", "length", "return"}`` of each episode.
    """
    stats = stats_from_fields({key: np.repeat(fields[key][None], episodes, 0) for key in fields})
    demos, _, _ = record_episodes(
        settings.task,
        np.repeat(solution[None], episodes, axis=0),
        stats,
        actor_hidden=settings.actor_hidden,
        obs_clip=settings.obs_clip,
        seed=seed,
        max_episode_steps=settings.max_episode_steps,
        task_kwargs=settings.task_kwargs,
        integrator=settings.integrator,
    )
    starts = np.r_[0, demos.episode_ends[:-1]]
    return [
        {
            "seed": seed + i,
            "length": int(end - start),
            "return": float(np.sum(demos.rewards[start:end], dtype=np.float64)),
        }
        for i, (start, end) in enumerate(zip(starts, demos.episode_ends, strict=True))
    ]


def export_policies(
    run_dir: str | Path,
    out: str | Path,
    fmt: str = "onnx",
    *,
    which: str = "true",
    cell: list[int] | None = None,
    top: int | None = None,
    episodes: int = 5,
    seed: int = 0,
) -> list[ExportedPolicy]:
    """Write elites of a run's archive as standalone policy files.

    Args:
        run_dir: a run directory with a checkpoint.
        out: the folder the files go to (made if missing).
        fmt: ``onnx`` (opset 18) or ``torch`` (a ``torch.export`` program, ``.pt2``).
        which: ``true`` (the paper's archive) or ``deployable`` (the run's own objective).
        cell: one grid cell, one index per measure; ``None`` with ``top`` unset: the best.
        top: K elites spread over the measure space from the best.
        episodes: deterministic scoring episodes per elite (their mean is
            ``corrected_return``).
        seed: reset seed of the first scoring episode.

    Returns:
        The files written, in the order chosen.

    Raises:
        ValueError: for an empty archive, a cell outside the grid or an empty cell, an
            unknown format, or an ``out`` that is a file.
        CheckpointError: for a run without a readable checkpoint.
    """
    run_dir, out = Path(run_dir), Path(out)
    if fmt not in SUFFIXES:
        raise ValueError(f"--format must be onnx, torch or minari, got {fmt!r}")
    if episodes < 1:
        raise ValueError(f"--episodes must be at least 1, got {episodes}")
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file; give a folder for the policy files")
    archive, iteration = load_archive(run_dir, which)
    elites = archive.data()
    rows = select_rows(archive, elites, cell, top)
    settings = ReplaySettings.of_run(run_dir)
    env = settings.make_env(1)
    low, high = env.single_action_space.low, env.single_action_space.high
    obs_dim = env.single_observation_space.shape[0]
    trained_with, (commit, dirty) = _training_commit(run_dir), git_state()
    written = []
    for row in rows:
        grid_cell = [int(i) for i in archive.int_to_grid_index([elites["index"][row]])[0]]
        fields = {key: elites[key][row] for key in ("obs_mean", "obs_var", "obs_count")}
        played = scoring_episodes(settings, elites["solution"][row], fields, episodes, seed)
        policy = GaitPolicy(
            elites["solution"][row],
            fields["obs_mean"],
            fields["obs_var"],
            settings.actor_hidden,
            settings.obs_clip,
            low,
            high,
        )
        stem = f"{which}_cell_{'_'.join(map(str, grid_cell))}"
        path = save_policy(policy, obs_dim, fmt, out / f"{stem}{SUFFIXES[fmt]}")
        metadata = {
            "task": settings.task,
            "task_kwargs": settings.task_kwargs,
            "integrator": settings.integrator,  # None: the task model's own (the v5 task)
            "max_episode_steps": settings.max_episode_steps,
            "file": path.name,
            "format": fmt,
            "input": {"name": "obs", "shape": ["batch", obs_dim], "dtype": "float32"},
            "output": {"name": "action", "shape": ["batch", len(low)], "dtype": "float32"},
            "archive": which,
            "cell": grid_cell,
            "measures": [float(m) for m in elites["measures"][row]],
            "objective": float(elites["objective"][row]),
            "corrected_return": float(np.mean([e["return"] for e in played])),
            "episodes": played,
            "run": str(run_dir),
            "iteration": iteration,
            "commit": trained_with,
            "exported_with": {"commit": commit, "dirty": dirty},
        }
        metadata_path = out / f"{stem}.json"
        text = json.dumps(metadata, indent=2) + "\n"
        atomic_write(metadata_path, lambda file, text=text: file.write(text.encode()))
        written.append(ExportedPolicy(path, metadata_path, metadata))
    return written
