"""``Experiment``: a run a researcher drives from Python, as ``qdil fit`` drives it.

Built from a recipe (with a seed, overrides and a runs folder) or reopened from a run
folder; run to the end with :meth:`Experiment.fit` or one iteration at a time with
:meth:`Experiment.step`, reading the metrics, archives, reward model and policy mean
between steps. The run folder's life (its ``config.yaml``, checkpoints, resume checks,
clean-up of a run that never started) belongs here; ``qdil fit`` is a shell around it.
"""

from __future__ import annotations

import contextlib
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from qdil.files import CONFIG_NAME
from qdil.recipe_load import LoadedRecipe, RecipeError, load_recipe, recipe_parser

if TYPE_CHECKING:
    import numpy as np
    from ribs.archives import ArchiveBase

    from qdil.rewards.base import RewardModel
    from qdil.run import Run
    from qdil.tracking import Tracker


def build_recipe(
    init: Any,
    name: str,
    run_dir: Path,
    resolved: str,
    *,
    resume: bool = False,
    tracker: type[Tracker] | None = None,
) -> Run:
    """The run of an instantiated recipe (jsonargparse's ``instantiate`` of a parsed one).

    Args:
        init: the instantiated recipe: its sections as objects.
        name: the run's name.
        run_dir: its folder.
        resolved: the resolved recipe as YAML (stored in checkpoints).
        resume: a checkpoint will be restored into the run (its reward pretraining is
            skipped: the checkpoint holds its result).
        tracker: the tracker's class (default: :class:`qdil.tracking.Tracker`).
    """
    import inspect

    import yaml

    from qdil.recipe import recipe
    from qdil.run import build_run

    # the recipe's sections, as recipe() declares them; ``name`` is the run's, given here
    sections = {key: init[key] for key in inspect.signature(recipe).parameters if key != "name"}
    options = {"tracker": tracker} if tracker is not None else {}
    return build_run(
        name=name,
        run_dir=run_dir,
        config=yaml.safe_load(resolved),
        resume=resume,
        **sections,
        **options,
    )


@dataclass
class RunFolder:
    """A checked recipe and the folder its run lives in, before anything is built or written.

    Attributes:
        loaded: the checked recipe.
        name: the run's name (``RUN_DIR``'s last part).
        run_dir: the run folder.
        resolved: the resolved recipe as YAML (what ``config.yaml`` holds).
        state: the last checkpoint's contents, or None for a run that starts afresh.
        finished: the checkpoint already reached ``qd.iterations`` (or the step budget).
    """

    loaded: LoadedRecipe
    name: str
    run_dir: Path
    resolved: str
    state: dict[str, Any] | None
    finished: bool

    @classmethod
    def of(cls, loaded: LoadedRecipe) -> RunFolder:
        """The folder of ``loaded``'s run, checked before anything is written.

        A new run's folder must hold no run; a resumed run's recipe must match its
        checkpoint's (but for the resumable keys).

        Raises:
            RecipeError: naming the folder and what to do.
        """
        import yaml

        from qdil.config import finished
        from qdil.qd.checkpoint import CHECKPOINT, read_checkpoint

        config = loaded.config
        name = config.name or f"{loaded.stem}-seed{config.seed}"
        run_dir = loaded.resume_dir or Path(config.logging.root) / name
        if loaded.resume_dir is None and (
            (run_dir / "checkpoints").exists() or (run_dir / "metrics.csv").exists()
        ):
            raise RecipeError(
                f"run directory {run_dir} already holds a run; continue it (or, without a "
                f"checkpoint, start it over) with `qdil fit --resume {run_dir}`, or choose "
                "another --name"
            )
        config.name = name
        resolved = recipe_parser().dump(config, skip_unset=False)
        state = None
        if loaded.resume_dir is not None and (run_dir / CHECKPOINT).exists():
            state = read_checkpoint(run_dir / CHECKPOINT)
            check_unchanged(state, yaml.safe_load(resolved), run_dir)
        done = state is not None and finished(config.qd, state["iteration"], state["env_steps"])
        return cls(loaded, name, run_dir, resolved, state, done)


def _stem(recipe: dict[str, Any]) -> str:
    """``walker2d_gail``: the task's first word and the reward model's registered name."""
    from qdil.rewards.names import declared_name

    env, reward = recipe.get("env") or {}, recipe["reward"]
    task = str(env.get("task", "Walker2d-v5") if isinstance(env, dict) else "task")
    path = str(reward.get("class_path", "") if isinstance(reward, dict) else reward)
    model = declared_name(path) if "." in path else path
    return f"{task.split('-')[0].lower()}_{model or path.rpartition('.')[2].lower()}"


def check_unchanged(state: dict[str, Any], resolved: dict[str, Any], run_dir: Path) -> None:
    """Refuse a resume whose recipe differs from the one stored with its checkpoint.

    Raises:
        RecipeError: naming the keys that differ and what to do.
    """
    from qdil.qd.checkpoint import config_differences
    from qdil.upgrades import upgraded

    stored = state.get("config")
    if stored is None:  # written before checkpoints stored their recipe
        return
    changed = config_differences(upgraded(stored), resolved)
    if changed:
        lines = "\n".join(f"  {line}" for line in changed)
        raise RecipeError(
            f"{run_dir / CONFIG_NAME} no longer matches the recipe its checkpoint was made "
            f"with (checkpoint -> now):\n{lines}\nRestore these keys to resume, or start a new "
            f"run from the edited file with `qdil fit {run_dir / CONFIG_NAME} --name NEW_NAME`. "
            "Only qd.iterations, qd.env_steps, env.num_threads, executor.* and logging.* may "
            "change on resume."
        )


class Experiment:
    """A built run and its folder: step it, fit it, read it, close it.

    Use :meth:`from_recipe` or :meth:`resume`; close it (or use it as a context manager) to
    stop its executor and finish its trackers.

    Attributes:
        run: every component of the run (:class:`qdil.run.Run`).
        run_dir: its folder.
        notes: what opening the folder did that a user should hear (a removed temporary
            file, a run started over, the iteration resumed at).
        metrics: the last iteration's metrics (empty before the first step).
    """

    def __init__(self, run: Run, notes: list[str]) -> None:
        self.run, self.run_dir, self.notes = run, run.run_dir, notes
        self.metrics: dict[str, float] = {}
        self._saved = time.monotonic()

    @classmethod
    def from_recipe(
        cls,
        recipe: str | Path,
        overrides: list[str] | tuple[str, ...] = (),
        *,
        seed: int | None = None,
        root: str | Path | None = None,
        name: str | None = None,
        tracker: type[Tracker] | None = None,
    ) -> Experiment:
        """Build a new run from a recipe file.

        Args:
            recipe: a recipe (YAML).
            overrides: command-line style overrides (``["--qd.iterations", "5"]``).
            seed: the run's seed (default: the recipe's).
            root: the runs folder (default: the recipe's ``logging.root``).
            name: the run's name (default: the recipe's stem and seed, as ``qdil fit``).
            tracker: the class that records each iteration: :class:`qdil.tracking.Tracker`
                (the default: ``metrics.csv``, and W&B as ``logging.wandb`` says) or a
                subclass of it.

        Raises:
            RecipeError: a bad recipe or override, or a folder that already holds a run.
        """
        extra = [*overrides]
        for key, value in (("--seed", seed), ("--logging.root", root), ("--name", name)):
            if value is not None:
                extra += [key, str(value)]
        return cls.open(RunFolder.of(load_recipe(recipe, extra)), tracker)

    @classmethod
    def from_parts(
        cls,
        *,
        env: Any,
        reward: Any,
        qd: Any,
        seed: int = 0,
        root: str | Path | None = None,
        name: str | None = None,
        tracker: type[Tracker] | None = None,
        **sections: Any,
    ) -> Experiment:
        """Build a new run from Python objects, without a recipe file.

        Args:
            env: the task and its simulations (``qdil.config.EnvConfig``).
            reward: a reward model class, ``functools.partial(Class, key=value)`` with its
                options, or a registered name (``"gail"``).
            qd: archives, emitter, scheduler (``qdil.config.QDConfig``; its ``emitter`` and
                ``scheduler`` classes or partials).
            seed: the run's seed.
            root: the runs folder (default: ``logging.root``).
            name: the run's name (default: the task's and the reward model's, and the seed:
                ``walker2d_gail-seed0``).
            tracker: the class that records each iteration (see :meth:`from_recipe`).
            **sections: ``policy``, ``rl`` (a class or partial; ``None`` for gradient-free
                emitters), ``bonus``, ``demos``, ``logging``, ``executor``
                (:func:`qdil.recipe_parts.recipe_of`).

        Raises:
            RecipeError: an object a recipe cannot record, a bad value, or a folder that
                already holds a run.
        """
        from qdil.recipe_parts import recipe_of

        recipe = recipe_of(env=env, reward=reward, qd=qd, seed=seed, **sections)
        extra = []
        for key, value in (("--logging.root", root), ("--name", name)):
            if value is not None:
                extra += [key, str(value)]
        loaded = load_recipe(recipe, extra, stem=_stem(recipe))
        return cls.open(RunFolder.of(loaded), tracker)

    @classmethod
    def resume(
        cls,
        run_dir: str | Path,
        overrides: list[str] | tuple[str, ...] = (),
        tracker: type[Tracker] | None = None,
    ) -> Experiment:
        """Reopen a run folder at its last checkpoint (or start it over if it has none).

        Args:
            run_dir: a folder made by ``qdil fit`` or :meth:`from_recipe`.
            overrides: the resumable keys only (``qd.iterations``, ``logging.*``, ...).
            tracker: the class that records each iteration (see :meth:`from_recipe`).
        """
        return cls.open(RunFolder.of(load_recipe(run_dir, overrides, resume=True)), tracker)

    @classmethod
    def open(cls, folder: RunFolder, tracker: type[Tracker] | None = None) -> Experiment:
        """Build the run of a checked folder and write its ``config.yaml``.

        A run that never started leaves no folder behind if building fails.
        """
        from qdil.files import atomic_write, remove_stale_temporaries
        from qdil.provenance import record_start
        from qdil.qd.checkpoint import CHECKPOINT, load_checkpoint

        run_dir, notes = folder.run_dir, []
        for path in remove_stale_temporaries(run_dir, run_dir / CHECKPOINT.parent):
            notes.append(f"removed {path}, left by a killed write")
        if folder.loaded.resume_dir is not None and folder.state is None:
            notes.append(
                f"{run_dir} has no checkpoint (the run stopped before its first one); "
                f"starting it over from its {CONFIG_NAME}"
            )
        fresh = not run_dir.exists()
        made = [parent for parent in run_dir.absolute().parents if not parent.exists()]
        run_dir.mkdir(parents=True, exist_ok=True)
        try:
            atomic_write(run_dir / CONFIG_NAME, lambda file: file.write(folder.resolved.encode()))
            init = recipe_parser().instantiate(folder.loaded.config)
            run = build_recipe(
                init,
                folder.name,
                run_dir,
                folder.resolved,
                resume=folder.state is not None,
                tracker=tracker,
            )
        except BaseException:
            if fresh:  # a run that never started leaves no directory behind, nor its root
                shutil.rmtree(run_dir, ignore_errors=True)
                for parent in made:  # innermost first; one another process wrote into stays
                    with contextlib.suppress(OSError):
                        parent.rmdir()
            raise
        if folder.state is not None:
            load_checkpoint(run, folder.state)
            folder.state = None  # restored into the run; free the checkpoint's bytes
            notes.append(f"resuming {run_dir} at iteration {run.state.iteration}")
        tracker = cast("Tracker", run.tracker)
        if tracker.csv.path.exists():  # rows logged after the checkpoint (all, if none)
            tracker.csv.truncate(run.state.iteration)
        note = record_start(run_dir, run.state.iteration)
        if note is not None:
            notes.append(f"warning: {run_dir} is {note}")
        return cls(run, notes)

    @property
    def iteration(self) -> int:
        """QD iterations done."""
        return self.run.state.iteration

    @property
    def finished(self) -> bool:
        """Whether ``qd.iterations`` (or the env-step budget) is reached."""
        from qdil.config import finished

        return finished(self.run.qd, self.run.state.iteration, self.run.state.env_steps)

    @property
    def archive(self) -> ArchiveBase:
        """The search archive (a pyribs archive): the one the scheduler inserts into."""
        return self.run.archives.main

    @property
    def reward_model(self) -> RewardModel:
        """The reward handed to RL (with its exploration bonus, if the recipe has one)."""
        return self.run.reward

    @property
    def policy_mean(self) -> np.ndarray | None:
        """θ_μ, the search policy's (D,) parameters (None without a gradient estimator)."""
        return None if self.run.emitter is None else self.run.emitter.theta

    def step(self) -> dict[str, float]:
        """Run one QD iteration: log its metrics, checkpoint when due; returns the metrics.

        Raises:
            RuntimeError: if the run is finished (raise ``qd.iterations`` on resume).
        """
        from qdil.qd.loop import next_iteration

        if self.finished:
            raise RuntimeError(f"{self.run_dir} is finished at iteration {self.iteration}")
        self.metrics, self._saved = next_iteration(self.run, self._saved)
        return self.metrics

    def fit(self) -> None:
        """Run iterations to the end, with a progress bar; checkpoint as the recipe says."""
        from qdil.qd.loop import run_qd

        run_qd(self.run)

    def checkpoint(self) -> None:
        """Save a checkpoint now (a resume continues from here)."""
        from qdil.qd.checkpoint import save_checkpoint

        with self.run.own_torch_rng():  # the checkpoint keeps the run's generator state
            save_checkpoint(self.run)
        self._saved = time.monotonic()

    def close(self) -> None:
        """Stop the executor's workers and finish the trackers (the CSV, W&B)."""
        try:
            self.run.executor.close()
        finally:
            cast("Tracker", self.run.tracker).finish(self.run)

    def __enter__(self) -> Experiment:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()
