"""Demonstrations from an expert archive, as the paper makes them.

:func:`demos_from_run` picks diverse elites among the best of a run's true-return archive
(:func:`select_elites`) and plays one deterministic episode of each (:func:`record_episodes`).
The steps, and why the returns differ from the archive's: docs/concepts/demonstrations.md.
"""

from __future__ import annotations

import datetime
from importlib.metadata import version
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml

from qdil.demos.dataset import DemoSet
from qdil.envs.vector import LocomotionVectorEnv
from qdil.files import CONFIG_NAME
from qdil.provenance import git_state
from qdil.rl.collect import ActionMap
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from qdil.rl.sampler import act
from qdil.upgrades import policy_settings


def farthest_point_sampling(points: np.ndarray, num: int, start: int = 0) -> np.ndarray:
    """Indices of ``num`` points chosen greedily to maximise the distance to those chosen.

    Args:
        points: (n, k) points (elite measures).
        num: how many to choose (at most n).
        start: the first choice (the best elite).

    Returns:
        (num,) indices, ``start`` first.
    """
    points = np.asarray(points, dtype=np.float64)
    num = min(num, len(points))
    chosen = [start]
    distance = np.linalg.norm(points - points[start], axis=1)
    for _ in range(num - 1):
        nxt = int(np.argmax(distance))
        chosen.append(nxt)
        distance = np.minimum(distance, np.linalg.norm(points - points[nxt], axis=1))
    return np.array(chosen)


def select_elites(elites: dict[str, np.ndarray], top: int, num: int) -> np.ndarray:
    """Rows of ``elites`` (pyribs archive data) to demonstrate: diverse among the best.

    Args:
        elites: archive data with ``objective`` and ``measures``.
        top: size of the candidate pool, ranked by objective.
        num: demonstrations to pick.

    Returns:
        (num,) row indices into ``elites``, the best first.
    """
    order = np.argsort(-elites["objective"], kind="stable")[:top]
    picks = farthest_point_sampling(elites["measures"][order], num, start=0)
    return order[picks]


def record_episodes(
    task: str,
    solutions: np.ndarray,
    stats: RunningMeanStd,
    *,
    actor_hidden: tuple[int, ...] = (128, 128),
    obs_clip: float = 10.0,
    seed: int = 0,
    max_episode_steps: int = 1000,
    task_kwargs: dict[str, Any] | None = None,
    integrator: str | None = None,
) -> tuple[DemoSet, np.ndarray, np.ndarray]:
    """One deterministic episode per policy, recorded step by step.

    Args:
        task: gymnasium task id.
        solutions: (P, D) policies.
        stats: their observation statistics (P policies).
        actor_hidden: actor widths of the run.
        obs_clip: the run's bound of normalised observations.
        seed: reset seed (policy i's episode starts from seed + i).
        max_episode_steps: horizon.
        task_kwargs: gymnasium keyword arguments of the task.
        integrator: ``env.integrator`` of the run (None: the task model's own).

    Returns:
        The demonstrations and the (T, nq), (T, nv) MuJoCo states of each s_t.
    """
    num = len(solutions)
    env = LocomotionVectorEnv(
        task,
        num,
        max_episode_steps=max_episode_steps,
        autoreset_mode="Disabled",
        integrator=integrator,
        **(task_kwargs or {}),
    )
    actor = VectorizedActor(
        num, env.single_observation_space.shape[0], env.single_action_space.shape[0], actor_hidden
    )
    actor.set_solutions(solutions)
    action_map = ActionMap(env.single_action_space.low, env.single_action_space.high)
    obs, info = env.reset(seed=seed)
    contacts = info["foot_contact"]
    running = np.ones(num, dtype=bool)
    episodes: list[dict[str, list]] = [
        {key: [] for key in ("obs", "actions", "contacts", "rewards", "qpos", "qvel")}
        for _ in range(num)
    ]
    finals: list[dict[str, Any]] = [{} for _ in range(num)]
    while running.any():
        _, actions, _ = act(actor, stats, torch.from_numpy(obs).float(), obs_clip, None, True)
        executed = action_map(actions).numpy().astype(np.float64)
        qpos, qvel = env.physics.view("qpos").copy(), env.physics.view("qvel").copy()
        next_obs, reward, terminated, truncated, info = env.step(executed, mask=running)
        for i in np.flatnonzero(running):
            episode = episodes[i]
            for key, value in (
                ("obs", obs[i]),
                ("actions", executed[i]),
                ("contacts", contacts[i]),
                ("rewards", reward[i]),
                ("qpos", qpos[i]),
                ("qvel", qvel[i]),
            ):
                episode[key].append(value)
            if terminated[i] or truncated[i]:
                running[i] = False
                finals[i] = {
                    "obs": next_obs[i],
                    "contacts": info["foot_contact"][i],
                    "terminated": bool(terminated[i]),
                }
        obs, contacts = next_obs, info["foot_contact"]
    stacked = {key: np.concatenate([np.asarray(e[key]) for e in episodes]) for key in episodes[0]}
    ends = np.cumsum([len(e["obs"]) for e in episodes])
    final_obs = np.stack([f["obs"] for f in finals])
    final_contacts = np.stack([f["contacts"] for f in finals])
    next_obs_all = np.roll(stacked["obs"], -1, axis=0)
    next_contacts_all = np.roll(stacked["contacts"], -1, axis=0)
    next_obs_all[ends - 1], next_contacts_all[ends - 1] = final_obs, final_contacts
    demos = DemoSet(
        task=task,
        obs=stacked["obs"],
        actions=stacked["actions"],
        contacts=stacked["contacts"].astype(np.float32),
        rewards=stacked["rewards"],
        next_obs=next_obs_all,
        next_contacts=next_contacts_all.astype(np.float32),
        episode_ends=ends,
        terminated=np.array([f["terminated"] for f in finals]),
    )
    return demos, stacked["qpos"], stacked["qvel"]


def demos_from_run(
    run_dir: str | Path,
    archive: Any,
    iteration: int,
    top: int = 500,
    num: int = 4,
    seed: int = 0,
) -> tuple[DemoSet, np.ndarray, np.ndarray]:
    """The paper's pipeline on a run directory: select elites, record their episodes.

    Args:
        run_dir: the run (its ``config.yaml`` says the task and the policies' shape).
        archive: the run's true-keyed pyribs archive, as
            :func:`qdil.qd.checkpoint.load_archive` reads it (the caller loads it: the
            demonstrations sit below the QD loop).
        iteration: the iteration the archive was saved at (recorded in the metadata).
        top: elites to choose among, best first.
        num: demonstrations to record.
        seed: reset seed of the episodes.

    Raises:
        ValueError: if the archive holds no elites.
    """
    run_dir = Path(run_dir)
    config = yaml.safe_load((run_dir / CONFIG_NAME).read_text())
    elites = archive.data()
    if len(elites["objective"]) == 0:
        raise ValueError(f"{run_dir}: the archive holds no elites yet")
    rows = select_elites(elites, top, num)
    actor_hidden, obs_clip = policy_settings(config)
    env = config["env"]
    stats = RunningMeanStd.__new__(RunningMeanStd)
    stats.mean = torch.as_tensor(elites["obs_mean"][rows], dtype=torch.float64)
    stats.var = torch.as_tensor(elites["obs_var"][rows], dtype=torch.float64)
    stats.count = torch.as_tensor(elites["obs_count"][rows], dtype=torch.float64)
    demos, qpos, qvel = record_episodes(
        env["task"],
        elites["solution"][rows],
        stats,
        actor_hidden=actor_hidden,
        obs_clip=obs_clip,
        seed=seed,
        max_episode_steps=int(env.get("max_episode_steps", 1000)),
        task_kwargs=env.get("task_kwargs") or {},
        integrator=env.get("integrator"),
    )
    commit, dirty = git_state()
    metadata = {
        "task": env["task"],
        "run": str(run_dir.resolve()),
        "run_name": config.get("name"),
        "run_seed": config.get("seed"),
        "run_iteration": iteration,
        "recipe": config,
        "reset_seed": seed,
        "deterministic": True,
        "qdil_version": version("qdil"),
        "git_commit": commit,
        "git_dirty": dirty,
        "created": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "selection": {
            "top": top,
            "num": num,
            "method": "farthest-point sampling in measure space from the best elite",
        },
        "elites": [
            {
                "archive_index": int(elites["index"][r]),
                "archive_objective": float(elites["objective"][r]),
                "archive_measures": elites["measures"][r].tolist(),
            }
            for r in rows
        ],
    }
    return DemoSet(**{**demos.__dict__, "metadata": metadata}), qpos, qvel
