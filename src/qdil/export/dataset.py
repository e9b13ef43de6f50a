"""``qdil export --format minari``: rollouts of chosen elites as a local Minari dataset.

Each elite plays deterministic episodes on qdil's C engine (equal to gymnasium's task);
every step keeps its observation, action, reward, termination and truncation, and, in
``infos``, the foot contacts of its state and the elite's measures and cell. qdil reads
such a dataset back as demonstrations (``qdil demos --import-minari``).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from qdil.demos.generate import record_episodes
from qdil.evaluation.elites import select_rows
from qdil.evaluation.rescore import ReplaySettings
from qdil.provenance import git_state
from qdil.qd.checkpoint import load_archive
from qdil.rl.normalize import stats_from_fields


def export_dataset(
    run_dir: str | Path,
    dataset_id: str,
    *,
    which: str = "true",
    cell: list[int] | None = None,
    top: int | None = None,
    episodes: int = 1,
    seed: int = 0,
) -> Any:
    """Write rollouts of elites of a run's archive as a local Minari dataset.

    Args:
        run_dir: a run directory with a checkpoint.
        dataset_id: the dataset's Minari id, e.g. ``qdil/walker2d/gaits-v0``; it is written
            under ``MINARI_DATASETS_PATH`` (default ``~/.minari/datasets``).
        which: ``true`` (the paper's archive) or ``deployable``.
        cell: one grid cell; ``None`` with ``top`` unset: the best elite.
        top: K elites spread over the measure space from the best.
        episodes: deterministic episodes per elite; elite j's episode i is reset with
            ``seed + j * episodes + i``.
        seed: the first reset seed.

    Returns:
        The ``minari.MinariDataset`` written.

    Raises:
        ImportError: without the ``minari`` package.
        ValueError: for an empty archive, a bad cell, or a dataset id that exists already.
    """
    try:
        import minari
        from minari.data_collector.episode_buffer import EpisodeBuffer
    except ImportError as error:
        raise ImportError("--format minari needs `pip install minari`") from error
    if episodes < 1:
        raise ValueError(f"--episodes must be at least 1, got {episodes}")
    folder = os.environ.get("MINARI_DATASETS_PATH")
    if folder and not os.path.isabs(folder):  # minari joins a relative one onto itself
        os.environ["MINARI_DATASETS_PATH"] = os.path.abspath(folder)
    if dataset_id in minari.list_local_datasets():
        raise ValueError(
            f"the Minari dataset {dataset_id!r} exists already "
            f"({minari.storage.get_dataset_path(dataset_id)}); choose another name or version"
        )
    run_dir = Path(run_dir)
    archive, iteration = load_archive(run_dir, which)
    elites = archive.data()
    rows = np.repeat(select_rows(archive, elites, cell, top), episodes)
    settings = ReplaySettings.of_run(run_dir)
    fields = {key: elites[key][rows] for key in ("obs_mean", "obs_var", "obs_count")}
    demos, _, _ = record_episodes(
        settings.task,
        elites["solution"][rows],
        stats_from_fields(fields),
        actor_hidden=settings.actor_hidden,
        obs_clip=settings.obs_clip,
        seed=seed,
        max_episode_steps=settings.max_episode_steps,
        task_kwargs=settings.task_kwargs,
        integrator=settings.integrator,
    )
    cells = archive.int_to_grid_index(elites["index"][rows])
    buffers = []
    for i, (a, b) in enumerate(zip(demos.episode_starts, demos.episode_ends, strict=True)):
        steps, ended = b - a, bool(demos.terminated[i])
        states = b - a + 1  # s_0 .. s_T: Minari keeps the reset's info and every step's
        buffers.append(
            EpisodeBuffer(
                id=i,
                seed=seed + i,
                observations=np.vstack([demos.obs[a:b], demos.next_obs[b - 1]]),
                actions=demos.actions[a:b],
                rewards=demos.rewards[a:b],
                terminations=np.r_[np.zeros(steps - 1, bool), ended],
                truncations=np.r_[np.zeros(steps - 1, bool), not ended],
                infos={
                    "foot_contact": np.vstack([demos.contacts[a:b], demos.next_contacts[b - 1]]),
                    "measures": np.repeat(elites["measures"][rows[i]][None], states, axis=0),
                    "cell": np.repeat(np.asarray(cells[i])[None], states, axis=0),
                },
            )
        )
    env = gym.make(
        settings.task, max_episode_steps=settings.max_episode_steps, **settings.task_kwargs
    )
    commit, _ = git_state()
    permalink = f"https://github.com/qdil/qdil/tree/{commit}" if commit else None
    description = (
        f"{len(set(rows.tolist()))} elites of the {which} archive of qdil run {run_dir} "
        f"(iteration {iteration}), {episodes} deterministic episode(s) each; infos: "
        f"foot_contact of each state, the elite's measures and cell. qdil commit {commit}."
    )
    if settings.integrator is not None:  # the env spec below is gymnasium's task
        description += f" Stepped with MuJoCo's {settings.integrator} integrator (env.integrator)."
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*author.*")  # no person to name here
        warnings.filterwarnings("ignore", message=".*code_permalink.*")  # none without a commit
        return minari.create_dataset_from_buffers(
            dataset_id,
            buffer=buffers,
            env=env,
            eval_env=env.spec,
            algorithm_name="qdil",
            code_permalink=permalink,
            description=description,
            data_format="hdf5",
        )
