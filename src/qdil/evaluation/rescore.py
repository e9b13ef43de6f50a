"""``qdil eval``: re-score every elite on the true reward (PPGA's corrected metrics, D12).

:func:`rescore_archive` replays every elite of a run's two policy archives on deterministic
episodes and writes the corrected archives and ``eval.json``; :func:`rescore` does one
archive. Why, and what it costs: docs/guides/reproduce-paper-results.md.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from ribs.archives import GridArchive

from qdil.envs.faces import torch_face
from qdil.envs.vector import LocomotionVectorEnv
from qdil.files import CONFIG_NAME, atomic_write
from qdil.provenance import provenance
from qdil.qd.archives import QD_OFFSETS, elite_fields, make_grid, qd_metrics, true_keyed
from qdil.qd.checkpoint import dumps_compact, load_archive, load_archives
from qdil.rl.episodes import evaluate_policies
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd, stats_from_fields
from qdil.upgrades import policy_settings

CORRECTED = "corrected_archive.pkl"
CORRECTED_DEPLOYABLE = "corrected_deployable.pkl"
EVAL_JSON = "eval.json"


@dataclass(frozen=True)
class ReplaySettings:
    """How a run's policies are replayed: its task, horizon and actor, from ``config.yaml``.

    Attributes:
        task: gymnasium task id.
        max_episode_steps: the run's horizon.
        task_kwargs: gymnasium keyword arguments of the task.
        integrator: ``env.integrator`` (None: the task model's own).
        actor_hidden: widths of the actor's hidden layers.
        obs_clip: bound of normalised observations.
    """

    task: str
    max_episode_steps: int
    task_kwargs: dict[str, Any]
    actor_hidden: tuple[int, ...]
    obs_clip: float
    integrator: str | None = None

    @classmethod
    def of_run(cls, run_dir: str | Path) -> ReplaySettings:
        """The settings of the run in ``run_dir`` (its ``env`` and ``policy`` sections)."""
        config = yaml.safe_load((Path(run_dir) / CONFIG_NAME).read_text())
        env = config["env"]
        actor_hidden, obs_clip = policy_settings(config)
        return cls(
            task=env["task"],
            max_episode_steps=int(env.get("max_episode_steps", 1000)),
            task_kwargs=env.get("task_kwargs") or {},
            actor_hidden=actor_hidden,
            obs_clip=obs_clip,
            integrator=env.get("integrator"),
        )

    def make_env(
        self, num_envs: int, num_threads: int | None = None, max_episode_steps: int | None = None
    ) -> LocomotionVectorEnv:
        """The task on the reference C backend, autoreset disabled (episodes are played whole).

        Args:
            num_envs: simulations N.
            num_threads: physics threads (``None``: every core).
            max_episode_steps: horizon (``None``: the run's).
        """
        return LocomotionVectorEnv(
            self.task,
            num_envs,
            max_episode_steps=max_episode_steps or self.max_episode_steps,
            autoreset_mode="Disabled",
            num_threads=num_threads,
            integrator=self.integrator,
            **self.task_kwargs,
        )


def elite_policies(
    elites: dict[str, np.ndarray],
    rows: np.ndarray,
    env: LocomotionVectorEnv,
    actor_hidden: tuple[int, ...],
) -> tuple[VectorizedActor, RunningMeanStd]:
    """The policies of archive rows ``rows`` with their own observation statistics.

    Args:
        elites: pyribs archive data with ``solution`` (n, D), ``obs_mean`` (n, obs_dim),
            ``obs_var`` (n, obs_dim) and ``obs_count`` (n,).
        rows: (P,) rows to rebuild.
        env: the task (for the observation and action sizes).
        actor_hidden: widths of the actor's hidden layers.

    Returns:
        P actors and their (P, obs_dim) statistics.
    """
    obs_dim = env.single_observation_space.shape[0]
    action_dim = env.single_action_space.shape[0]
    actor = VectorizedActor(len(rows), obs_dim, action_dim, actor_hidden)
    actor.set_solutions(elites["solution"][rows])
    fields = {key: elites[key][rows] for key in ("obs_mean", "obs_var", "obs_count")}
    return actor, stats_from_fields(fields)


def rescore(
    run_dir: str | Path,
    which: str = "true",
    episodes: int = 5,
    batch: int = 64,
    seed: int = 0,
    num_threads: int | None = None,
    progress: bool = False,
    loaded: tuple[GridArchive, int] | None = None,
) -> tuple[GridArchive, dict[str, Any]]:
    """Re-evaluate every elite of one of a run's policy archives (no file is written).

    Args:
        run_dir: the run directory.
        which: ``true`` (the paper's archive) or ``deployable``.
        episodes: deterministic episodes per elite (PPGA: 50).
        batch: elites evaluated together.
        seed: reset seed (elite i's episodes reset with seeds from ``seed + i·episodes``).
        num_threads: physics threads (``None``: every core).
        progress: show a progress bar.
        loaded: the archive and its iteration, where the caller read the checkpoint already.

    Returns:
        The corrected archive, whose elites carry ``return_se`` (the standard error of
        their mean return over the episodes), and a summary: ``metrics`` (corrected),
        ``training_metrics`` (the elites' true returns as scored in training),
        ``qd_score_se`` (standard error of the corrected QD-Score over episodes), and for
        the deployable archive ``learned_metrics`` (by the objective that chose its elites).

    Raises:
        CheckpointError: the run has no checkpoint, or one without this archive.
    """
    settings = ReplaySettings.of_run(run_dir)
    archive, iteration = loaded or load_archive(run_dir, which)
    elites = archive.data()
    count = len(elites["objective"])
    width = min(batch, max(count, 1))
    env = settings.make_env(width * episodes, num_threads)
    face = torch_face(env)
    obs_dim = env.single_observation_space.shape[0]
    objective, measures, lengths = np.zeros(count), np.zeros((count, env.num_feet)), np.zeros(count)
    spread = np.zeros(count)
    steps = 0
    from tqdm.auto import tqdm

    for start in tqdm(
        range(0, count, width), disable=not progress, desc=f"re-evaluating {which}", unit="batch"
    ):
        rows = np.arange(start, min(start + width, count))
        actor, stats = elite_policies(elites, rows, env, settings.actor_hidden)
        result = evaluate_policies(
            face, actor, stats, episodes, seed + start * episodes, None, True, settings.obs_clip
        )
        objective[rows], measures[rows], lengths[rows] = (
            result.true_objective,
            result.measures,
            result.lengths,
        )
        spread[rows] = result.true_std
        steps += result.env_steps
    corrected = make_grid(
        solution_dim=archive.solution_dim,
        cells=list(archive.dims),
        extra_fields=elite_fields(obs_dim) | {"return_se": ((), np.float64)},
    )
    if count:
        corrected.add(
            elites["solution"],
            objective,
            measures,
            obs_mean=elites["obs_mean"],
            obs_var=elites["obs_var"],
            obs_count=elites["obs_count"],
            length=lengths,
            return_se=spread / np.sqrt(episodes),
        )
    offset = QD_OFFSETS.get(settings.task, 0.0)
    kept_se = corrected.data(["return_se"])["return_se"]
    summary = {
        "iteration": iteration,
        "elites_evaluated": count,
        "env_steps": steps,
        "metrics": qd_metrics(corrected, offset),
        "qd_score_se": float(np.sqrt(np.sum(kept_se**2))),
        "training_metrics": qd_metrics(
            true_keyed(archive) if which == "deployable" else archive, offset
        ),
    }
    if which == "deployable":
        summary["learned_metrics"] = qd_metrics(archive, offset)
    return corrected, summary


def same_elites(first: GridArchive, second: GridArchive) -> bool:
    """Whether two archives hold the same elites (solutions, objectives, cells) in one order."""
    keys = ["index", "solution", "objective", "measures", "obs_mean", "obs_var", "obs_count"]
    if len(first) != len(second):
        return False
    one, other = first.data(keys), second.data(keys)
    return all(np.array_equal(one[key], other[key]) for key in keys)


def rescore_archive(
    run_dir: str | Path,
    episodes: int = 5,
    batch: int = 64,
    seed: int = 0,
    num_threads: int | None = None,
    progress: bool = False,
) -> tuple[GridArchive, dict[str, Any]]:
    """Re-evaluate every elite of a run's two policy archives; write the results.

    Writes ``corrected_archive.pkl`` (the true-keyed archive corrected),
    ``corrected_deployable.pkl`` and ``eval.json``. A checkpoint from before the deployable
    archive existed gives ``"deployable": null``.

    Args:
        run_dir: the run directory.
        episodes: deterministic episodes per elite (PPGA: 50).
        batch: elites evaluated together.
        seed: reset seed (see :func:`rescore`).
        num_threads: physics threads (``None``: every core).
        progress: show a progress bar.

    Returns:
        The corrected true-keyed archive and ``eval.json``'s content: the true-keyed
        archive's summary (:func:`rescore`) at the top level, the deployable one's under
        ``deployable``, the settings and the provenance.
    """
    run_dir = Path(run_dir)
    task = yaml.safe_load((run_dir / CONFIG_NAME).read_text())["env"]["task"]
    settings = (episodes, batch, seed, num_threads, progress)
    archives, iteration = load_archives(run_dir)  # one read of the (large) checkpoint
    corrected, found = rescore(run_dir, "true", *settings, (archives["true"], iteration))
    summary = {
        "run": str(run_dir),
        "task": task,
        "iteration": found["iteration"],
        "episodes_per_elite": episodes,
        "reset_seed": seed,
        "deterministic": True,
        **{key: value for key, value in found.items() if key != "iteration"},
        "deployable": None,
        "provenance": provenance(),
    }
    corrected_bytes = dumps_compact(corrected)
    deployable = archives["deployable"]  # None: a checkpoint that predates it
    if deployable is not None:
        if same_elites(deployable, archives["true"]):
            # a run that ranks by the true return keeps the same elites in both archives, in
            # the same order: their scores would be the same episodes, so they are played once
            # (the archive-side metrics are the deployable archive's own, computed as its
            # played summary would compute them: sums in another storage order differ in
            # the last bit)
            offset = QD_OFFSETS.get(task, 0.0)
            summary["deployable"] = {
                **found,
                "training_metrics": qd_metrics(true_keyed(deployable), offset),
                "learned_metrics": qd_metrics(deployable, offset),
                "same_as_true": True,
            }
            deployable_bytes = corrected_bytes
        else:
            loaded = (deployable, iteration)
            deployable, summary["deployable"] = rescore(run_dir, "deployable", *settings, loaded)
            deployable_bytes = dumps_compact(deployable)
        atomic_write(run_dir / CORRECTED_DEPLOYABLE, lambda f: f.write(deployable_bytes))
    atomic_write(run_dir / CORRECTED, lambda f: f.write(corrected_bytes))
    atomic_write(run_dir / EVAL_JSON, lambda f: f.write(json.dumps(summary, indent=1).encode()))
    return corrected, summary
