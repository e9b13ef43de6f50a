"""Wiring a recipe into a runnable QD-IL run (and back from a run directory on resume)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import lightning as L
import numpy as np
import torch
from ribs.schedulers import Scheduler

from qdil.config import BonusConfig, DemoConfig, EnvConfig, LoggingConfig, QDConfig, RewardFactory
from qdil.demos.io import load_demos
from qdil.devices import DEVICE_BACKENDS, fabric_settings
from qdil.envs.vector import LocomotionVectorEnv
from qdil.executors.base import Executor
from qdil.qd.archives import RunArchives, deployable_fields, elite_fields, make_grid
from qdil.qd.emitter import PPGAEmitter
from qdil.qd.state import LoopState, Run
from qdil.rewards.base import RewardModel
from qdil.rewards.bonus import ExplorationBonus
from qdil.rewards.ebc import EBCBonus
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from qdil.rl.vppo import VPPO
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


def build_run(
    *,
    name: str,
    run_dir: Path,
    seed: int,
    env: EnvConfig,
    rl: VPPO,
    reward: RewardFactory,
    bonus: BonusConfig,
    demos: DemoConfig,
    qd: QDConfig,
    logging: LoggingConfig,
    config: dict[str, Any],
    resume: bool = False,
    executor: Executor | None = None,
) -> Run:
    """Build every component of a run from the instantiated recipe sections.

    With ``resume``, the reward model's offline pretraining is skipped: the checkpoint
    that :func:`~qdil.qd.checkpoint.load_checkpoint` restores next holds its result.
    ``executor`` steps VPPO's simulations (default: here, :class:`LocalExecutor`).

    ``env.device`` places the run: the physics, policies, VPPO, the reward model (Fabric's
    accelerator) and the bonus run there; pyribs and xNES stay on the host.

    Raises:
        ValueError: for inconsistent settings, naming the recipe key (``env.device`` for
            a device the run cannot use).
    """
    _, vppo_seed, emitter_seed, archive_seed, loop_seed, torch_seed, x0_seed = _seeds(seed, 7)
    torch.manual_seed(torch_seed)

    # ---- environments and the policy space
    train_env = LocomotionVectorEnv(
        env.task,
        env.num_envs,
        max_episode_steps=env.max_episode_steps,
        autoreset_mode="SameStep",
        num_threads=env.num_threads,
        backend=env.backend,
        device=env.device,
        **env.task_kwargs,
    )
    device = train_env.device  # checked with env.backend before anything was built
    obs_dim = train_env.single_observation_space.shape[0]
    action_dim = train_env.single_action_space.shape[0]
    k = train_env.num_feet
    solution_dim = VectorizedActor.solution_dim(obs_dim, action_dim, rl.actor_hidden)

    # ---- archives, emitter, scheduler (pyribs)
    fields = elite_fields(obs_dim)
    cells = [qd.cells] * k
    archive_seeds = np.random.SeedSequence(archive_seed).generate_state(3)
    main = make_grid(
        solution_dim=solution_dim,
        cells=cells,
        extra_fields=fields,
        learning_rate=qd.archive_learning_rate,
        threshold_min=qd.threshold_min,
        seed=int(archive_seeds[0]),
    )
    archives = RunArchives(
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
    x0 = VectorizedActor.initial_solution(obs_dim, action_dim, rl.actor_hidden, x0_seed)
    theta_stats = RunningMeanStd(1, (obs_dim,))
    theta_fields = {
        "obs_mean": theta_stats.mean[0].numpy(),
        "obs_var": theta_stats.var[0].numpy(),
        "obs_count": theta_stats.count[0].numpy(),
    }
    if qd.emitter is None:
        emitter = PPGAEmitter(main, x0, seed=emitter_seed)
    else:
        emitter = qd.emitter(main, x0, seed=emitter_seed)
    if not hasattr(emitter, "theta_fields"):
        raise ValueError(
            "qd.emitter must be a PPGA-style emitter with theta, theta_fields and "
            "coefficient_mean (e.g. qdil.qd.PPGAEmitter)"
        )
    emitter.theta_fields = theta_fields
    scheduler = (
        Scheduler(main, [emitter], add_mode="batch")
        if qd.scheduler is None
        else qd.scheduler(main, [emitter])
    )

    # ---- evaluation environment and VPPO
    branch_slots = emitter.batch_size * qd.branch_episodes
    # a device scores θ_μ and the branches side by side (fewer steps in sequence); the
    # C engine plays them one after the other, so its environment fits the larger one
    on_device = env.backend in DEVICE_BACKENDS
    together, larger = branch_slots + qd.mean_episodes, max(branch_slots, qd.mean_episodes)
    eval_size = env.eval_envs or (together if on_device else larger)
    eval_env = LocomotionVectorEnv(
        env.task,
        eval_size,
        max_episode_steps=env.max_episode_steps,
        autoreset_mode="Disabled",
        num_threads=env.num_threads,
        backend=env.backend,
        device=device,
        **env.task_kwargs,
    )
    rl.setup(train_env, eval_env, vppo_seed, executor)

    # ---- reward model, driven by Lightning Fabric; the bonus wraps it afterwards
    model = reward(obs_dim, action_dim, k)
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
    demo_set = None
    if model.needs_demos:
        if demos.path is None:
            label = model.name or type(model).__name__
            raise ValueError(f"demos.path: the {label} reward model needs demonstrations")
        demo_set = load_demos(demos.path, task=env.task, num_episodes=demos.num_episodes)
    model.setup(demo_set)
    if not resume:  # a resumed run's checkpoint holds the pretrained weights
        model.pretrain(demo_set)
    expert = demo_set.transitions().to(device) if demo_set is not None else None

    run_dir.mkdir(parents=True, exist_ok=True)
    tracker = Tracker(run_dir, logging, name, config)
    return Run(
        name=name,
        run_dir=run_dir,
        task=env.task,
        seed=seed,
        qd=qd,
        logging=logging,
        env=train_env,
        eval_env=eval_env,
        vppo=rl,
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
    )
