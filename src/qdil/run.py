"""Wiring a recipe into a runnable QD-IL run (and back from a run directory on resume)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import lightning as L
import numpy as np
import torch
from ribs.archives import k_means_centroids

from qdil.config import (
    BonusConfig,
    DemoConfig,
    EnvConfig,
    LoggingConfig,
    PolicyConfig,
    QDConfig,
    RewardFactory,
)
from qdil.demos.dataset import DemoSet
from qdil.demos.io import load_demos
from qdil.devices import DEVICE_BACKENDS, fabric_settings
from qdil.envs.vector import LocomotionVectorEnv
from qdil.executors.base import Executor
from qdil.executors.local import LocalExecutor
from qdil.files import atomic_write
from qdil.qd.archives import (
    CENTROIDS,
    RunArchives,
    deployable_fields,
    elite_fields,
    make_cvt,
    make_grid,
)
from qdil.qd.scoring import Scorer
from qdil.qd.search import make_search, search_emitters
from qdil.qd.state import LoopState, Run
from qdil.rewards.base import RewardModel, check_demos
from qdil.rewards.bonus import ExplorationBonus
from qdil.rewards.ebc import EBCBonus
from qdil.rl.networks import VectorizedActor
from qdil.seats import GradientEstimator, Scheduler
from qdil.tracking import Tracker


def _seeds(seed: int, count: int) -> list[int]:
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(count)]


def with_bonus(model: RewardModel, bonus: BonusConfig, archives: RunArchives) -> RewardModel:
    """``model`` wrapped in the recipe's exploration bonus, or ``model`` if it is disabled.

    Raises:
        ValueError: for a setting that does not apply to ``bonus.type``, naming its key.
    """
    problems = bonus.problems()
    if problems:
        raise ValueError("; ".join(problems))
    if not bonus.enabled:
        return model
    if bonus.type == "ebc":
        # read through the container: a resume replaces archives.main with the checkpoint's
        return EBCBonus(model, lambda: archives.main, weight=bonus.weight, offset=bonus.offset)
    return ExplorationBonus(
        model, weight=bonus.weight, cells=bonus.cells, in_fitness=bonus.in_fitness
    )


def _environment(
    env: EnvConfig, size: int, autoreset_mode: str, device: str | torch.device
) -> LocomotionVectorEnv:
    """``size`` batched simulations of the recipe's task, on its backend and ``device``.

    Args:
        env: The recipe's ``env`` section.
        size: How many simulations the batch holds.
        autoreset_mode: ``"SameStep"`` for training rollouts, ``"Disabled"`` for
            evaluation episodes.
        device: ``env.device`` for the first environment; the checked ``torch.device``
            it exposes for every later one.

    Raises:
        ValueError: for a backend or device the run cannot use, naming ``env.device``.
    """
    return LocomotionVectorEnv(
        env.task,
        size,
        max_episode_steps=env.max_episode_steps,
        autoreset_mode=autoreset_mode,
        num_threads=env.num_threads,
        backend=env.backend,
        device=device,
        deterministic=env.deterministic,
        integrator=env.integrator,
        **env.task_kwargs,
    )


def _centroids(qd: QDConfig, k: int, seed: int, run_dir: Path) -> np.ndarray:
    """The CVT search archive's (cells, k) centroids: made once, then read from the run.

    k-means' last bits may differ between CPUs, so the run keeps the centroids it made in
    ``centroids.npy`` and a resume reads them (the checkpoint's archive holds them too).
    """
    path = run_dir / CENTROIDS
    if path.is_file():
        centroids = np.load(path)
        if centroids.shape == (qd.archive.centroids, k):
            return centroids
    centroids, _ = k_means_centroids(
        centroids=qd.archive.centroids,
        ranges=[(0.0, 1.0)] * k,
        samples=qd.archive.samples,
        seed=seed,
    )
    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda file: np.save(file, centroids))
    return centroids


def _archives(
    qd: QDConfig, solution_dim: int, obs_dim: int, k: int, seed: int, run_dir: Path
) -> RunArchives:
    """The run's archives over ``k`` foot-contact measures: search, true and deployable.

    Args:
        qd: The recipe's ``qd`` section (cells per measure, the search archive, CMA-MAE's
            learning rate and threshold).
        solution_dim: Length of a policy's flat parameter vector.
        obs_dim: Observation size (the elites keep their observation statistics).
        k: Number of measures (feet).
        seed: Seeds the three archives, in the order main, true, deployable (and the CVT
            archive's k-means after them).
        run_dir: Where a CVT archive's centroids are kept.
    """
    fields = elite_fields(obs_dim)
    cells = [qd.cells] * k
    archive_seeds = np.random.SeedSequence(seed).generate_state(4)
    search = {
        "solution_dim": solution_dim,
        "extra_fields": fields,
        "learning_rate": qd.archive_learning_rate,
        "threshold_min": qd.threshold_min,
        "seed": int(archive_seeds[0]),
    }
    if qd.archive.type == "cvt":
        centroids = _centroids(qd, k, int(archive_seeds[3]), run_dir)
        main = make_cvt(centroids=centroids, **search)
    else:
        main = make_grid(cells=cells, **search)
    return RunArchives(
        main=main,
        true=make_grid(
            solution_dim=solution_dim, cells=cells, extra_fields=fields, seed=int(archive_seeds[1])
        ),
        deployable=make_grid(
            solution_dim=solution_dim,
            cells=cells,
            extra_fields=deployable_fields(obs_dim),
            seed=int(archive_seeds[2]),
        ),
    )


def _eval_size(
    env: EnvConfig, qd: QDConfig, scheduler: Scheduler, estimator: GradientEstimator | None
) -> int:
    """How many simulations the evaluation environment holds (``env.eval_envs`` if set).

    A device scores θ_μ and the branches side by side (fewer steps in sequence); the C
    engine plays them one after the other, so its environment fits the larger of the two.
    An estimator that plays episodes itself (``eval_slots``: ES gradients) plays them alone.
    Without an estimator every emitter's solutions play together (a bandit's whole pool).
    """
    branch_slots = sum(e.batch_size for e in search_emitters(scheduler)) * qd.branch_episodes
    own = int(getattr(estimator, "eval_slots", 0))
    if env.eval_envs and env.eval_envs < own:
        raise ValueError(
            f"env.eval_envs={env.eval_envs}: the gradient estimator plays {own} episodes at "
            f"once; set env.eval_envs to at least {own}, or to null"
        )
    if env.eval_envs:
        return env.eval_envs
    if estimator is None:
        return branch_slots
    if env.backend in DEVICE_BACKENDS:
        return max(branch_slots + qd.mean_episodes, own)
    return max(branch_slots, qd.mean_episodes, own)


def _reward_model(
    reward: RewardFactory,
    bonus: BonusConfig,
    archives: RunArchives,
    train_env: LocomotionVectorEnv,
) -> tuple[RewardModel, list[torch.optim.Optimizer], L.Fabric]:
    """The recipe's reward model set up with Lightning Fabric, its bonus wrapped around it.

    Args:
        reward: Builds the model from the observation, action and measure sizes.
        bonus: The recipe's ``bonus`` section.
        archives: The run's archives (the EBC bonus reads the main one).
        train_env: The training environment: its sizes and device.

    Returns:
        The (wrapped) model on the run's device, its optimisers as Fabric set them up
        (none for a model that does not learn), and the Fabric that drives them.

    Raises:
        ValueError: for a factory that does not build a qdil ``RewardModel`` or a bonus
            setting that does not apply, naming the recipe key.
    """
    device = train_env.device
    model = reward(
        train_env.single_observation_space.shape[0],
        train_env.single_action_space.shape[0],
        train_env.num_feet,
    )
    if not isinstance(model, RewardModel):
        raise ValueError(f"reward: {type(model).__name__} is not a qdil RewardModel")
    fabric = L.Fabric(**fabric_settings(device))
    optimizers = model.configure_optimizers() if model.learned else None
    if optimizers is None:
        optimizers = []
    elif not isinstance(optimizers, list | tuple):
        optimizers = [optimizers]
    if optimizers:
        _, *optimizers = fabric.setup(model, *optimizers)
    # the bonus's counts and models without optimisers (which Fabric does not set up) too
    model = with_bonus(model, bonus, archives).to(device)
    return model, optimizers, fabric


def _demos(model: RewardModel, demos: DemoConfig, task: str) -> DemoSet | None:
    """The recipe's demonstrations, or ``None`` for a reward model that needs none.

    Raises:
        ValueError: when ``model`` needs demonstrations and ``demos.path`` is unset.
    """
    check_demos(model, demos.path)
    if not model.needs_demos:
        return None
    return load_demos(demos.path, task=task, num_episodes=demos.num_episodes)


def set_up_policies(
    train_env: LocomotionVectorEnv,
    eval_env: LocomotionVectorEnv,
    estimator: GradientEstimator | None,
    policy: PolicyConfig | None = None,
    executor: Executor | None = None,
    seed: int = 0,
) -> tuple[Executor, Scorer, torch.Generator]:
    """The executor, scorer and action noise of a run's policies, the estimator bound to them.

    Args:
        train_env: the estimator's ``SAME_STEP`` simulations.
        eval_env: the evaluations' ``DISABLED`` simulations, on the same device.
        estimator: the gradient estimator to set up (``None``: gradient-free emitters).
        policy: the policy family (default: the paper's).
        executor: who steps the simulations (default: here, :class:`LocalExecutor`).
        seed: seeds the action noise and the estimator.

    Returns:
        The executor (set up), the scorer, and the noise generator they share.
    """
    policy = PolicyConfig() if policy is None else policy
    executor = LocalExecutor() if executor is None else executor
    executor.setup(train_env, eval_env, policy.obs_clip)
    noise = torch.Generator(device=train_env.device).manual_seed(seed)
    if estimator is not None:
        estimator.setup(train_env, executor, policy, noise, seed)
    return executor, Scorer(executor, train_env, policy, noise), noise


def build_run(
    *,
    name: str,
    run_dir: Path,
    seed: int,
    env: EnvConfig,
    rl: GradientEstimator | None,
    reward: RewardFactory,
    bonus: BonusConfig,
    demos: DemoConfig,
    qd: QDConfig,
    logging: LoggingConfig,
    config: dict[str, Any],
    policy: PolicyConfig | None = None,
    resume: bool = False,
    executor: Executor | None = None,
    tracker: type[Tracker] = Tracker,
) -> Run:
    """Build every component of a run from the instantiated recipe sections.

    The steps, in the order their random draws are made: the training environment, the
    archives, the emitter and scheduler, the evaluation environment, the executor, the
    scorer and the gradient estimator, the reward model and its demonstrations, the tracker.

    ``policy`` is the policy family of the archive's solutions (default: the paper's).
    With ``resume``, the reward model's offline pretraining is skipped: the checkpoint
    that :func:`~qdil.qd.checkpoint.load_checkpoint` restores next holds its result.
    ``executor`` steps the simulations (default: here, :class:`LocalExecutor`).
    ``tracker`` records each iteration: :class:`~qdil.tracking.Tracker` (``metrics.csv``,
    and W&B as ``logging`` says) or a subclass of it, built with the run's folder, logging
    section, name and recipe.

    ``env.device`` places the run: the physics, policies, the estimator, the reward model
    (Fabric's accelerator) and the bonus run there; pyribs and xNES stay on the host.

    Raises:
        ValueError: for inconsistent settings, naming the recipe key (``env.device`` for
            a device the run cannot use).
    """
    _, rl_seed, emitter_seed, archive_seed, loop_seed, torch_seed, x0_seed = _seeds(seed, 7)
    # the networks draw their first weights from torch's global generator: seeded for the
    # run here, the caller's state given back after (a run changes no one's random state)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(torch_seed)
        policy = PolicyConfig() if policy is None else policy

        train_env = _environment(env, env.num_envs, "SameStep", env.device)
        device = train_env.device  # checked with env.backend before anything was built
        obs_dim = train_env.single_observation_space.shape[0]
        action_dim = train_env.single_action_space.shape[0]
        solution_dim = VectorizedActor.solution_dim(obs_dim, action_dim, policy.hidden)

        archives = _archives(qd, solution_dim, obs_dim, train_env.num_feet, archive_seed, run_dir)
        x0 = VectorizedActor.initial_solution(obs_dim, action_dim, policy.hidden, x0_seed)
        emitter, scheduler = make_search(
            qd, archives.main, x0, obs_dim, [emitter_seed, *_seeds(emitter_seed, qd.emitters - 1)],
            rl is not None,
        )  # fmt: skip

        eval_env = _environment(env, _eval_size(env, qd, scheduler, rl), "Disabled", device)
        executor, scorer, noise = set_up_policies(
            train_env, eval_env, rl, policy, executor, rl_seed
        )

        model, optimizers, fabric = _reward_model(reward, bonus, archives, train_env)
        if rl is None and model.needs_log_probs:
            raise ValueError(
                "rl: null: the reward model needs log-probs of the policy it rewards (AIRL), "
                "which gradient-free emitters do not have (no one policy acts); use an estimator"
            )
        demo_set = _demos(model, demos, env.task)
        model.setup(demo_set)
        if not resume:  # a resumed run's checkpoint holds the pretrained weights
            model.pretrain(demo_set)
        expert = demo_set.transitions().to(device) if demo_set is not None else None

        torch_rng = torch.get_rng_state()  # the run's, lent back by Run.own_torch_rng
        run_dir.mkdir(parents=True, exist_ok=True)
        tracker = tracker(run_dir, logging, name, config)
        return Run(
            name=name,
            run_dir=run_dir,
            task=env.task,
            seed=seed,
            qd=qd,
            logging=logging,
            env=train_env,
            eval_env=eval_env,
            executor=executor,
            scorer=scorer,
            noise=noise,
            estimator=rl,
            reward=model,
            reward_optimizers=optimizers,
            fabric=fabric,
            scheduler=scheduler,
            emitter=emitter,
            archives=archives,
            demos=demo_set,
            expert=expert,
            state=LoopState(rng=np.random.default_rng(loop_seed)),
            tracker=tracker,
            config=config,
            torch_rng=torch_rng,
        )
