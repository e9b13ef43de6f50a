"""Recipe sections: typed, documented once, validated by jsonargparse.

A recipe is one YAML file with the sections ``seed``, ``name``, ``env``, ``policy``, ``rl``,
``reward``, ``bonus``, ``demos``, ``qd`` and ``logging``. Classes are chosen with jsonargparse's
``class_path``/``init_args`` (LightningCLI's dialect): ``rl`` (the gradient estimator),
``reward`` (a reward model, or its registered name), ``qd.emitter`` and ``qd.scheduler``; the
seats they fill are declared in :mod:`qdil.seats`.
Every default lives in a signature here or in the chosen class, so it is documented once.
"""

from __future__ import annotations

import typing
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Literal

import numpy as np
from ribs.archives import ArchiveBase

from qdil.seats import Emitter, Scheduler

if TYPE_CHECKING:
    from qdil.rewards.base import RewardModel

# "RewardModel" is a forward reference: the recipe sections sit below the reward models and do
# not import them; jsonargparse resolves it in qdil.recipe, which does. typing's Callable, since
# Python 3.11's collections.abc.Callable flattens its argument list when resolving one.
RewardFactory = typing.Callable[[int, int, int], "RewardModel"]
"""A reward model class with its hyperparameters; qdil passes obs_dim, action_dim, k."""

EmitterFactory = Callable[[ArchiveBase, np.ndarray], Emitter]
"""An emitter class with its hyperparameters; qdil passes the search archive, θ_0 (as ``x0``)
and ``seed``."""

SchedulerFactory = Callable[[ArchiveBase, list[Emitter]], Scheduler]
"""A scheduler class with its options (pyribs'); qdil passes the archive and emitters."""


@dataclass
class Checked:
    """A recipe section whose numbers have smallest values, checked when it is built.

    A section built in Python (``EnvConfig(num_envs=0)``) is refused as a recipe file's
    would be, naming the key.

    Attributes:
        section: the section's name in a recipe.
        minimums: the smallest value of each numeric field that has one.
    """

    section: ClassVar[str] = ""
    minimums: ClassVar[dict[str, float]] = {}

    def range_problems(self) -> list[str]:
        """One message per field below its minimum (empty if all is well)."""
        return [
            problem
            for key, low in self.minimums.items()
            if (problem := below_minimum(f"{self.section}.{key}", getattr(self, key), low))
        ]

    def __post_init__(self) -> None:
        problems = self.range_problems()
        if problems:
            raise ValueError("; ".join(problems))


def below_minimum(key: str, value: Any, low: float) -> str | None:
    """The message for ``value`` of ``key`` under ``low``, or None (``None`` values pass)."""
    if isinstance(value, int | float) and not isinstance(value, bool) and value < low:
        return f"{key} must be at least {low}, got {value}; set it in the recipe or with --{key} N"
    return None


@dataclass
class PolicyConfig:
    """The policies that the archive's solutions are: their network and its input.

    Every solution is the flat parameter vector of one such policy (an MLP with tanh
    hidden layers, a Gaussian head and a per-action log standard deviation), run on
    observations normalised with the policy's own statistics.

    Attributes:
        hidden: widths of the hidden layers (the paper: 128, 128).
        obs_clip: bound of normalised observations.
    """

    hidden: tuple[int, ...] = (128, 128)
    obs_clip: float = 10.0


@dataclass
class EnvConfig(Checked):
    """The task and its simulations.

    Attributes:
        task: gymnasium task id: Walker2d-v5, HalfCheetah-v5, Humanoid-v5, Hopper-v5, Ant-v5.
        num_envs: simulations of the VPPO phases (the paper: 3000); divisible by k+1.
        eval_envs: simulations of the evaluations; ``null`` for λ·branch_episodes (or
            mean_episodes if larger), and on a device backend their sum, which scores the
            search policy and its branches side by side (below the sum: one after the other).
        num_threads: physics threads; ``null`` for every available core.
        backend: physics engine: ``mujoco`` (MuJoCo's C engine on the CPU, bit-identical to
            gymnasium) or ``warp`` (MuJoCo Warp, float32; ``pip install -e ".[warp]"``).
        device: where the run computes: ``cpu``, or ``cuda`` / ``cuda:N`` (``warp`` backend
            only). The physics, policies, VPPO, the reward model (Fabric's accelerator) and
            the bonus run there; pyribs and xNES stay on the host (docs/guides/gpu.md).
        deterministic: ``warp`` backend: MuJoCo Warp's deterministic kernels, so that a GPU
            run repeats bit for bit (without them it does not; docs/guides/gpu.md). The
            ``mujoco`` backend and Warp's CPU device repeat without them.
        integrator: ``euler``, ``rk4``, ``implicit`` or ``implicitfast`` in place of the task
            model's own (Walker2d, Hopper, Humanoid, Ant: RK4; HalfCheetah: Euler); ``null``
            keeps it. Another than the task's own is not the gymnasium task: the run's name
            and its report's task say so (docs/guides/gpu.md#integrators).
        max_episode_steps: episode horizon (the paper: 1000).
        task_kwargs: gymnasium keyword arguments of the task (e.g. ``ctrl_cost_weight``).
    """

    section: ClassVar[str] = "env"
    minimums: ClassVar[dict[str, float]] = {
        "num_envs": 1,
        "eval_envs": 1,
        "num_threads": 1,
        "max_episode_steps": 1,
    }

    task: str = "Walker2d-v5"
    num_envs: int = 3000
    eval_envs: int | None = None
    num_threads: int | None = None
    backend: Literal["mujoco", "warp"] = "mujoco"
    device: str = "cpu"
    deterministic: bool = False
    integrator: Literal["euler", "rk4", "implicit", "implicitfast"] | None = None
    max_episode_steps: int = 1000
    task_kwargs: dict[str, Any] = field(default_factory=dict)


@dataclass
class SearchArchiveConfig:
    """The search (CMA-MAE) archive: the grid of ``qd.cells``, or a CVT archive.

    Only the archive the emitter and scheduler search in changes; the reported true and
    deployable archives stay the grid of ``qd.cells``, so metrics stay comparable.

    Attributes:
        type: ``grid`` (``qd.cells`` per measure) or ``cvt`` (pyribs' ``CVTArchive``: cells
            are the Voronoi regions of ``centroids`` points in the measure space).
        centroids: ``cvt``: how many cells; the centroids come from k-means over ``samples``
            uniform points, made once and kept with the run (``centroids.npy``).
        samples: ``cvt``: uniform points the k-means runs over.
    """

    type: Literal["grid", "cvt"] = "grid"
    centroids: int = 2500
    samples: int = 100_000


@dataclass
class QDConfig(Checked):
    """The quality-diversity side: archives, emitter, scheduler, evaluation.

    Attributes:
        iterations: QD iterations (the paper: 2000).
        env_steps: a budget in simulated env steps (``null``: none): the run stops at the
            end of the first iteration that reaches it, or at ``iterations``, whichever
            comes first, so that methods with different steps per iteration compare at
            equal cost.
        cells: grid cells per measure (the paper: 50, i.e. 50×50 for two feet).
        archive_learning_rate: CMA-MAE archive learning rate α.
        threshold_min: CMA-MAE minimum threshold.
        branch_episodes: episodes scoring each branched solution (PPGA: 10).
        mean_episodes: episodes scoring the search policy θ_μ (PPGA: all 3000 envs).
        deterministic_eval: score with mean actions (PPGA samples: False).
        fitness: ``reward``: the archive's objective is the return under the reward model
            (decision D1; imitation). ``true``: the true return (an oracle, as the public
            QD-IL code does; not imitation).
        emitter: emitter class and hyperparameters (default: ``qdil.qd.PPGAEmitter``).
        emitters: how many emitters the scheduler gets, each from ``emitter`` with a seed
            of its own (1 beside a gradient estimator; sep-CMA-MAE: several).
        scheduler: pyribs scheduler class and options (default: ``ribs.schedulers.Scheduler``).
        archive: the search archive: the grid of ``cells`` (default) or a CVT archive.
    """

    section: ClassVar[str] = "qd"
    minimums: ClassVar[dict[str, float]] = {
        "iterations": 1,
        "env_steps": 1,
        "cells": 1,
        "branch_episodes": 1,
        "mean_episodes": 1,
        "emitters": 1,
    }

    iterations: int = 2000
    env_steps: int | None = None
    cells: int = 50
    archive_learning_rate: float = 0.5
    threshold_min: float = 200.0
    branch_episodes: int = 10
    mean_episodes: int = 100
    deterministic_eval: bool = False
    fitness: Literal["reward", "true"] = "reward"
    emitter: EmitterFactory | None = None
    emitters: int = 1
    scheduler: SchedulerFactory | None = None
    archive: SearchArchiveConfig = field(default_factory=SearchArchiveConfig)


def finished(qd: QDConfig | Any, iteration: int, env_steps: int) -> bool:
    """Whether a run that completed ``iteration`` after ``env_steps`` env steps stops there.

    Args:
        qd: the recipe's ``qd`` section (a :class:`QDConfig` or the parsed namespace).
        iteration: QD iterations completed.
        env_steps: env steps simulated by then.
    """
    budget = qd.env_steps
    return iteration >= qd.iterations or (budget is not None and env_steps >= budget)


@dataclass
class DemoConfig(Checked):
    """Demonstrations for the reward model.

    Attributes:
        path: a qdil demonstration file (``.npz``); ``null`` when the reward needs none.
        num_episodes: use the first n episodes (``null``: all).
    """

    section: ClassVar[str] = "demos"
    minimums: ClassVar[dict[str, float]] = {"num_episodes": 1}

    path: str | None = None
    num_episodes: int | None = None


@dataclass
class BonusConfig(Checked):
    """An exploration bonus added to the reward model's rewards (any model).

    Attributes:
        enabled: add the bonus.
        type: ``single_step``: WQDIL's single-step archive bonus (decision D5),
            r_exp = 1 / (1 + p(δ(s))) on every step, training and evaluation
            (docs/rewards/bonus.md). ``ebc``: Extrinsic Behavioral Curiosity, offset + weight
            on every step of a training rollout whose mean measure falls in an unoccupied
            cell of the CMA-MAE archive (docs/rewards/ebc.md).
        weight: multiplier of the bonus: w of r_exp (the WQDIL paper: 1), or q of EBC (the
            EBC runners: 2).
        cells: ``single_step`` only: cells per measure of the single-step archive; ``null``
            uses the 2^k binary contact patterns (the measures are 0/1 flags).
        offset: ``ebc`` only: p, added to every training step whatever the cell (the EBC
            runners: 0).
        in_fitness: ``single_step`` only: evaluations get the bonus too, so the CMA-MAE
            archive and xNES rank by learned return + bonus (the paper's Algorithm 1, the
            default). ``false`` hands the bonus to training rollouts only, as EBC does: RL
            still explores, the archive ranks by the learned reward alone.
    """

    section: ClassVar[str] = "bonus"
    minimums: ClassVar[dict[str, float]] = {"cells": 1}

    enabled: bool = False
    type: Literal["single_step", "ebc"] = "single_step"
    weight: float = 1.0
    cells: int | None = None
    offset: float = 0.0
    in_fitness: bool = True

    def problems(self) -> list[str]:
        """Settings that do not apply to ``type``, each naming its key (empty if none)."""
        problems = []
        if self.type != "single_step" and self.cells is not None:
            problems.append(
                f"bonus.cells applies to bonus.type single_step only (the {self.type} bonus "
                f"uses the archive's qd.cells); remove it or set it to null, got {self.cells}"
            )
        if self.type != "ebc" and self.offset != 0.0:
            problems.append(
                f"bonus.offset applies to bonus.type ebc only; remove it or set it to 0, "
                f"got {self.offset}"
            )
        if self.type != "single_step" and not self.in_fitness:
            problems.append(
                f"bonus.in_fitness applies to bonus.type single_step only (the {self.type} "
                f"bonus never enters the archive's objective); remove it or set it to true"
            )
        return problems


@dataclass
class LoggingConfig(Checked):
    """Where a run writes and what it logs.

    Attributes:
        root: parent folder of run directories.
        checkpoint_every: save a checkpoint every K iterations (and at the end).
        checkpoint_minutes: also save one at the end of the first iteration that ends this
            many minutes of wall time after the last save (or the start), so that a run
            killed early or between distant checkpoints loses little; 0 saves by iteration
            count only.
        progress: show a progress bar.
        wandb: ``offline`` (default; no network, sync later with ``wandb sync``),
            ``online``, or ``disabled``.
        wandb_project: W&B project.
        wandb_group: W&B group of the run (``null``: none; ``qdil sweep`` sets the sweep's
            name, so that a sweep's runs show together).
        heatmap_every: log an archive heatmap every K iterations (0: never).
        videos: at the end of the run, render this many elites of the deployable archive,
            spread over the measure space, and log their gaits to W&B (0: none; W&B only;
            without headless OpenGL one line says so and the run ends as usual).
    """

    section: ClassVar[str] = "logging"
    minimums: ClassVar[dict[str, float]] = {
        "checkpoint_every": 1,
        "checkpoint_minutes": 0,
        "heatmap_every": 0,
    }

    root: str = "runs"
    checkpoint_every: int = 10
    checkpoint_minutes: float = 30.0
    progress: bool = True
    wandb: Literal["offline", "online", "disabled"] = "offline"
    wandb_project: str = "qdil"
    wandb_group: str | None = None
    heatmap_every: int = 25
    videos: int = 4
