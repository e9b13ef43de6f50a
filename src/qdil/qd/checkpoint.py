"""Checkpoints: everything a killed run needs to continue as if it had never stopped.

:func:`save_checkpoint` replaces ``checkpoints/last.pt`` atomically, archives pickled with
their occupied cells only (:func:`dumps_compact`); :func:`load_checkpoint` restores a run,
:func:`load_archives` a run's archives alone, and :func:`config_differences` names the recipe
keys a resume would change. What a checkpoint holds, and resuming: docs/concepts/recipes.md.
"""

from __future__ import annotations

import io
import pickle
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from ribs.archives import ArrayStore

from qdil.files import atomic_write

if TYPE_CHECKING:
    from qdil.qd.state import Run

FORMAT_VERSION = 1
CHECKPOINT = Path("checkpoints") / "last.pt"
# Recipe keys a resume may change: they set how long the run goes on and what it writes,
# not what it computes (physics threads and the executor change speed only: a run stopped
# on a cluster may resume locally, and the other way round).
RESUMABLE_KEYS = ("qd.iterations", "qd.env_steps", "env.num_threads", "logging", "executor")
# Recipe keys added after checkpoints stored their recipe, with the value that runs made
# before them used implicitly: a checkpoint without the key resumes when it has that value.
IMPLICIT_KEYS = {
    "env.backend": "mujoco",
    "env.device": "cpu",
    "env.deterministic": False,
    "env.integrator": None,
    "reward.init_args.absorbing": None,
    "reward.init_args.reward_form": None,
    "reward.init_args.steps_per_update": None,
    "reward.init_args.feature_clip": None,
    "reward.init_args.min_gap": 1.0,
    "reward.init_args.calibration_samples": 8192,
    "reward.init_args.score_type": "f",
    "bonus.type": "single_step",
    "bonus.offset": 0.0,
    "bonus.in_fitness": True,
    "qd.emitters": 1,
    "qd.archive.type": "grid",
    "qd.archive.centroids": 2500,
    "qd.archive.samples": 100_000,
}


class CheckpointError(RuntimeError):
    """A checkpoint is missing, corrupt or from an incompatible run."""


def _flatten(value: Any, prefix: str = "") -> dict[str, Any]:
    """A nested mapping as ``{"a.b.c": leaf}`` (lists are leaves)."""
    if not isinstance(value, dict) or (prefix and not value):
        return {prefix: value}
    flat: dict[str, Any] = {}
    for key, item in value.items():
        flat |= _flatten(item, f"{prefix}.{key}" if prefix else str(key))
    return flat


def config_differences(
    stored: dict[str, Any], current: dict[str, Any], allowed: tuple[str, ...] = RESUMABLE_KEYS
) -> list[str]:
    """The recipe keys whose values differ between a checkpoint's config and the current one.

    Args:
        stored: the resolved recipe stored with the checkpoint.
        current: the resolved recipe the resume would run.
        allowed: keys (and sections) a resume may change; they are not compared.

    Returns:
        ``"key: stored -> current"`` for every differing key, sorted by key.
    """
    old, new = _flatten(stored), _flatten(current)
    old = {key: value for key, value in IMPLICIT_KEYS.items() if key in new} | old

    def compared(key: str) -> bool:
        return not any(key == name or key.startswith(f"{name}.") for name in allowed)

    def show(flat: dict[str, Any], key: str) -> str:
        return repr(flat[key]) if key in flat else "(absent)"

    return [
        f"{key}: {show(old, key)} -> {show(new, key)}"
        for key in sorted(set(old) | set(new))
        if compared(key) and (key not in old or key not in new or old[key] != new[key])
    ]


def _expand_store(state: dict[str, Any]) -> ArrayStore:
    """Rebuild an ``ArrayStore`` from :class:`_CompactPickler`'s occupied rows."""
    store = ArrayStore.__new__(ArrayStore)
    rows = state.pop("_qdil_rows")
    capacity = state["_props"]["capacity"]
    fields = {}
    for name, values in state["_fields"].items():
        # Unoccupied rows are never read: pyribs masks them with ``occupied`` (an
        # unoccupied cell's threshold is taken as threshold_min), so zeros are as good as
        # the uninitialised memory they replace.
        full = np.zeros((capacity, *values.shape[1:]), dtype=values.dtype)
        full[rows] = values
        fields[name] = full
    state["_fields"] = fields
    store.__setstate__(state)
    return store


class _CompactPickler(pickle.Pickler):
    """Pickles numpy-backed ``ArrayStore``s with their occupied rows only."""

    def reducer_override(self, obj: Any) -> Any:
        if type(obj) is not ArrayStore:
            return NotImplemented
        state = obj.__getstate__()
        if not all(isinstance(arr, np.ndarray) for arr in state["_fields"].values()):
            return NotImplemented  # torch / cupy stores: pickled whole
        props = dict(state["_props"])
        count = props["n_occupied"]
        rows = np.asarray(props["occupied_list"][:count]).copy()
        props["occupied_list"] = np.asarray(props["occupied_list"]).copy()
        props["occupied_list"][count:] = 0
        state["_props"] = props
        state["_fields"] = {name: np.asarray(arr)[rows] for name, arr in state["_fields"].items()}
        state["_qdil_rows"] = rows
        return _expand_store, (state,)


def dumps_compact(obj: Any) -> bytes:
    """``pickle.dumps`` that writes pyribs archives' occupied cells only."""
    buffer = io.BytesIO()
    _CompactPickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(obj)
    return buffer.getvalue()


def save_checkpoint(run: Run) -> Path:
    """Write the run's full state to ``<run_dir>/checkpoints/last.pt`` atomically."""
    reward = run.reward
    state = {
        "format": FORMAT_VERSION,
        "task": run.task,
        "iteration": run.state.iteration,
        "env_steps": run.state.env_steps,
        "seconds": run.state.seconds,
        "rng": run.state.rng.bit_generator.state,
        "torch_rng": torch.get_rng_state(),
        "scheduler": dumps_compact(run.scheduler),
        "true_archive": dumps_compact(run.archives.true),
        "deployable_archive": dumps_compact(run.archives.deployable),
        "rl": run.estimator.state_dict() if run.estimator is not None else {},
        "noise": run.noise.get_state(),
        "reward": {
            "class": f"{type(reward).__module__}.{type(reward).__qualname__}",
            "state_dict": reward.state_dict(),
            "optimizers": [opt.state_dict() for opt in run.reward_optimizers],
            "extra": reward.extra_state(),
        },
        "config": run.config,  # compared with config.yaml on resume
    }
    path = run.run_dir / CHECKPOINT
    # torch.save's default protocol 2 stores bytes as latin-1 text, a quarter larger.
    atomic_write(
        path, lambda file: torch.save(state, file, pickle_protocol=pickle.HIGHEST_PROTOCOL)
    )
    return path


def read_checkpoint(path: Path) -> dict[str, Any]:
    """The state :func:`save_checkpoint` wrote to ``path``.

    Raises:
        CheckpointError: if the file is missing, unreadable or of another format version.
    """
    if not path.exists():
        raise CheckpointError(f"no checkpoint at {path}; the run stopped before its first one")
    try:
        state = torch.load(path, weights_only=False)  # our own file: pickled pyribs objects
    except Exception as error:
        raise CheckpointError(f"{path} is not a readable qdil checkpoint: {error}") from error
    if not isinstance(state, dict) or state.get("format") != FORMAT_VERSION:
        found = state.get("format") if isinstance(state, dict) else None
        raise CheckpointError(
            f"{path} has format {found!r}; this qdil reads format {FORMAT_VERSION}"
        )
    return state


def load_checkpoint(run: Run, state: dict[str, Any] | None = None) -> None:
    """Restore :func:`save_checkpoint`'s state into a freshly built run of the same config.

    Args:
        run: the run, built from the same recipe.
        state: the checkpoint, if the caller has read it already (:func:`read_checkpoint`).

    Raises:
        CheckpointError: if the file is missing, unreadable, of another format version, or
            was written by a run of another task, reward model or policy size.
    """
    path = run.run_dir / CHECKPOINT
    if state is None:
        state = read_checkpoint(path)
    if state["task"] != run.task:
        raise CheckpointError(f"{path} belongs to a {state['task']} run, not {run.task}")
    reward_class = f"{type(run.reward).__module__}.{type(run.reward).__qualname__}"
    if state["reward"]["class"] != reward_class:
        raise CheckpointError(
            f"{path} holds a {state['reward']['class']} reward model; the config builds "
            f"{reward_class}"
        )
    scheduler = pickle.loads(state["scheduler"])
    stored_dim, built_dim = scheduler.archive.solution_dim, run.archives.main.solution_dim
    if stored_dim != built_dim:  # checkpoints without a stored config reach this
        raise CheckpointError(
            f"{path} holds policies of {stored_dim} parameters; the config builds "
            f"{built_dim} (was policy.hidden edited in config.yaml?); restore "
            "config.yaml or start a new run with another --name"
        )
    run.state.iteration = state["iteration"]
    run.state.env_steps = state["env_steps"]
    run.state.seconds = state["seconds"]
    run.state.rng = np.random.default_rng()
    run.state.rng.bit_generator.state = state["rng"]
    run.torch_rng = state["torch_rng"]  # lent to torch while the run computes
    run.scheduler = scheduler
    if run.estimator is not None:
        run.emitter = run.scheduler.emitters[0]
    run.archives.main = run.scheduler.archive
    run.archives.true = pickle.loads(state["true_archive"])
    if "deployable_archive" in state:
        run.archives.deployable = pickle.loads(state["deployable_archive"])
    else:  # a checkpoint from before the deployable archive kept objectives, no policies
        print(
            f"{path} predates the deployable archive (best policy per cell by the run's own "
            f"objective): it starts empty at iteration {state['iteration']}",
            file=sys.stderr,
        )
    # checkpoints from before the seats kept both under "vppo"
    estimator_state = state["rl"] if "rl" in state else state["vppo"]
    if run.estimator is not None:
        run.estimator.load_state_dict(estimator_state)
    run.noise.set_state(state["noise"] if "noise" in state else estimator_state["generator"])
    run.reward.load_state_dict(state["reward"]["state_dict"])
    for optimizer, opt_state in zip(
        run.reward_optimizers, state["reward"]["optimizers"], strict=True
    ):
        optimizer.load_state_dict(opt_state)
    run.reward.load_extra_state(state["reward"]["extra"])


def load_archives(
    run_dir: str | Path, names: tuple[str, ...] = ("true", "deployable")
) -> tuple[dict[str, Any], int]:
    """Archives of a run's last checkpoint, read once: ``true``, ``deployable``, ``main``.

    Args:
        run_dir: the run directory.
        names: which archives (``main`` is CMA-MAE's archive).

    Returns:
        The pyribs archives by name and the iteration they were saved at. A ``deployable``
        archive that the checkpoint predates is ``None``.

    Raises:
        CheckpointError: if the run has no readable checkpoint.
    """
    path = Path(run_dir) / CHECKPOINT
    if not path.exists():
        raise CheckpointError(
            f"{run_dir}: no checkpoint at {path} (the run stopped before its first one; "
            f"run `qdil fit --resume {run_dir}` to start it over)"
        )
    unknown = [name for name in names if name not in ("true", "deployable", "main")]
    if unknown:
        raise ValueError(f"which must be true, deployable or main, got {unknown[0]!r}")
    state = read_checkpoint(path)
    archives: dict[str, Any] = {}
    for name in names:
        if name == "main":
            archives[name] = pickle.loads(state["scheduler"]).archive
        else:
            pickled = state.get(f"{name}_archive")
            archives[name] = None if pickled is None else pickle.loads(pickled)
    return archives, state["iteration"]


def load_archive(run_dir: str | Path, which: str = "true") -> tuple[Any, int]:
    """An archive of a run's last checkpoint: ``true``, ``deployable`` or ``main`` (CMA-MAE).

    Returns:
        The pyribs archive and the iteration it was saved at.

    Raises:
        CheckpointError: if the run has no readable checkpoint, or one without a
            deployable archive when ``which`` is ``deployable``.
    """
    archives, iteration = load_archives(run_dir, (which,))
    if archives[which] is None:
        raise CheckpointError(
            f"{run_dir}: the checkpoint predates the deployable archive (qdil fit --resume "
            "starts one from the next iteration)"
        )
    return archives[which], iteration
