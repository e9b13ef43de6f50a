"""Demonstrations from outside qdil: plain arrays or a Minari dataset.

Outside data rarely carries foot contacts. They are recomputed by replaying each state in
MuJoCo: gymnasium's v5 observations hold the joint positions apart from the root's
horizontal coordinates (x for the planar robots, x and y for Humanoid and Ant) followed by
the velocities. Contacts with a flat floor do not depend on those coordinates, so zero is
put in their place and :class:`~qdil.envs.contacts.ContactProbe` scans the contacts at each
configuration, exactly as the environments define δ(s).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from qdil.demos.dataset import DemoSet
from qdil.demos.io import DemoFormatError, TaskShape
from qdil.envs import make_gymnasium_env
from qdil.envs.contacts import ContactProbe
from qdil.envs.tasks import TASKS

# root coordinates that v5 observations leave out, by default
_SKIPPED_QPOS = {
    "Walker2d-v5": 1,
    "HalfCheetah-v5": 1,
    "Hopper-v5": 1,
    "Humanoid-v5": 2,
    "Ant-v5": 2,
}


def qpos_from_obs(task: str, obs: np.ndarray) -> np.ndarray:
    """(T, nq) positions from (T, obs_dim) v5 observations, excluded root coordinates = 0."""
    env = make_gymnasium_env(TASKS[task].gym_id, quiet=True).unwrapped
    nq = env.model.nq
    skipped = _SKIPPED_QPOS[task]
    obs = np.atleast_2d(obs)
    qpos = np.zeros((len(obs), nq))
    qpos[:, skipped:] = obs[:, : nq - skipped]
    return qpos


def replay_contacts(task: str, obs: np.ndarray) -> np.ndarray:
    """(T, k) foot-contact flags δ(s) of observations ``obs`` (T, obs_dim)."""
    env = make_gymnasium_env(TASKS[task].gym_id, quiet=True).unwrapped
    probe = ContactProbe(env.model, TASKS[task].feet, TASKS[task].floor)
    return probe.batch(qpos_from_obs(task, obs))


def import_arrays(
    task: str,
    observations: Sequence[np.ndarray],
    actions: Sequence[np.ndarray],
    rewards: Sequence[np.ndarray] | None = None,
    terminated: Sequence[bool] | None = None,
    metadata: dict[str, Any] | None = None,
) -> DemoSet:
    """Demonstrations from per-episode arrays, contacts recomputed by replay.

    Args:
        task: gymnasium task id (``"Walker2d-v5"``).
        observations: per episode, (L + 1, obs_dim) observations s_0 … s_L, the last one
            after the final action (as Minari stores them).
        actions: per episode, (L, action_dim) actions a_0 … a_{L-1}.
        rewards: per episode, (L,) rewards; ``None`` stores NaN.
        terminated: per episode, whether it ended by termination; ``None``: unknown (False).
        metadata: provenance to keep.

    Raises:
        DemoFormatError: for misaligned or mis-sized arrays, naming the episode.
    """
    shape = TaskShape.of(task)
    if len(observations) != len(actions) or not observations:
        raise DemoFormatError(
            f"got {len(observations)} observation and {len(actions)} action episodes"
        )
    parts: dict[str, list[np.ndarray]] = {"obs": [], "next_obs": [], "actions": [], "rewards": []}
    for i, (obs, act) in enumerate(zip(observations, actions, strict=True)):
        obs, act = np.asarray(obs, dtype=np.float64), np.asarray(act, dtype=np.float64)
        if obs.ndim != 2 or obs.shape[1] != shape.obs_dim:
            raise DemoFormatError(
                f"episode {i}: observations must be (L+1, {shape.obs_dim}), got {obs.shape}"
            )
        if act.ndim != 2 or act.shape[1] != shape.action_dim or len(act) != len(obs) - 1:
            raise DemoFormatError(
                f"episode {i}: actions must be ({len(obs) - 1}, {shape.action_dim}) for "
                f"{len(obs)} observations, got {act.shape}"
            )
        if len(act) == 0:
            raise DemoFormatError(f"episode {i} is empty")
        reward = (
            np.full(len(act), np.nan) if rewards is None else np.asarray(rewards[i], np.float64)
        )
        if len(reward) != len(act):
            raise DemoFormatError(f"episode {i}: {len(reward)} rewards for {len(act)} actions")
        parts["obs"].append(obs[:-1])
        parts["next_obs"].append(obs[1:])
        parts["actions"].append(act)
        parts["rewards"].append(reward)
    obs = np.concatenate(parts["obs"])
    next_obs = np.concatenate(parts["next_obs"])
    ends = np.cumsum([len(a) for a in parts["actions"]])
    return DemoSet(
        task=task,
        obs=obs,
        actions=np.concatenate(parts["actions"]),
        contacts=replay_contacts(task, obs),
        rewards=np.concatenate(parts["rewards"]),
        next_obs=next_obs,
        next_contacts=replay_contacts(task, next_obs),
        episode_ends=ends,
        terminated=np.zeros(len(ends), bool)
        if terminated is None
        else np.asarray(terminated, bool),
        metadata={"imported": True, "contacts": "recomputed by replay", **(metadata or {})},
    )


def import_npz(path: str, task: str) -> DemoSet:
    """Demonstrations from a D4RL-style ``.npz``, contacts recomputed by replay.

    Keys: ``observations``, ``actions``, ``next_observations`` (T, ...); optional
    ``rewards`` (T,), and ``terminals`` / ``timeouts`` (T,) marking episode ends (else one
    episode).

    Raises:
        DemoFormatError: for missing keys, naming them.
    """
    with np.load(path) as data:
        missing = [
            k for k in ("observations", "actions", "next_observations") if k not in data.files
        ]
        if missing:
            raise DemoFormatError(f"{path}: missing arrays {missing} (D4RL layout expected)")
        arrays = {key: np.asarray(data[key]) for key in data.files}
    steps = len(arrays["actions"])
    ended = np.zeros(steps, dtype=bool)
    for key in ("terminals", "timeouts"):
        if key in arrays:
            ended |= arrays[key].astype(bool)
    ended[-1] = True
    ends = np.flatnonzero(ended) + 1
    starts = np.r_[0, ends[:-1]]
    spans = list(zip(starts, ends, strict=True))
    terminals = arrays.get("terminals", np.zeros(steps))
    return import_arrays(
        task,
        [
            np.vstack([arrays["observations"][a:b], arrays["next_observations"][b - 1]])
            for a, b in spans
        ],
        [arrays["actions"][a:b] for a, b in spans],
        rewards=[arrays["rewards"][a:b] for a, b in spans] if "rewards" in arrays else None,
        terminated=[bool(terminals[b - 1]) for _, b in spans],
        metadata={"source": str(path)},
    )


def import_minari(
    dataset: Any, task: str | None = None, num_episodes: int | None = None
) -> DemoSet:
    """Demonstrations from a Minari dataset (an object or a local dataset id).

    Needs the optional ``minari`` package and a dataset already on disk: qdil never
    downloads at run time.

    Raises:
        ImportError: if ``minari`` is not installed.
        FileNotFoundError: if the dataset id is not on disk (the message says how to get it).
        DemoFormatError: if the task cannot be told or the data does not fit it.
    """
    if isinstance(dataset, str):
        try:
            import minari
        except ImportError as error:
            raise ImportError("importing a Minari dataset needs `pip install minari`") from error
        try:
            dataset = minari.load_dataset(dataset, download=False)
        except FileNotFoundError as error:  # minari's own advice (download=True) is its API's
            where = minari.storage.get_dataset_path(dataset)
            raise FileNotFoundError(
                f"Minari dataset {dataset!r} is not on this machine (looked in {where}); "
                f"download it first with `minari download {dataset}` (or set "
                "MINARI_DATASETS_PATH to the folder that holds it), then run the import again. "
                "qdil never downloads at run time."
            ) from error
    if task is None:
        spec = getattr(dataset, "env_spec", None)
        task = getattr(spec, "id", None)
        task = task.split("/")[-1] if task else None
    if task not in TASKS:
        raise DemoFormatError(f"Minari dataset: cannot map env {task!r} to a qdil task; pass task=")
    episodes = list(dataset.iterate_episodes())[:num_episodes]
    return import_arrays(
        task,
        [e.observations for e in episodes],
        [e.actions for e in episodes],
        rewards=[e.rewards for e in episodes],
        terminated=[bool(np.asarray(e.terminations)[-1]) for e in episodes],
        metadata={"source": "minari", "dataset": str(getattr(dataset, "spec", dataset))},
    )
