"""Checkpoints: everything a killed run needs to continue as if it had never stopped.

A checkpoint holds the pyribs scheduler (CMA-MAE archive, emitter, xNES, their random
generators) pickled as bytes, the two passive archives, VPPO's critics, optimisers, return
statistics and noise generator, the reward model's parameters, optimiser states and extra
state, and the loop's counters and seed stream. Archives are pickled compactly: a pyribs
``ArrayStore`` preallocates every field for every cell (a 50×50 Walker2d archive holds 2,500
policies of ~15 k parameters whether or not the cells are occupied), so only the occupied
rows are written and the full arrays are rebuilt on load. It is written to a temporary file in the
same folder, flushed to disk and renamed over ``checkpoints/last.pt``, so a crash at any
moment leaves either the previous checkpoint or the new one, never half of one.
"""

from __future__ import annotations

import io
import os
import pickle
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from ribs.archives import ArrayStore

if TYPE_CHECKING:
    from qdil.run import Run

FORMAT_VERSION = 1
CHECKPOINT = Path("checkpoints") / "last.pt"


class CheckpointError(RuntimeError):
    """A checkpoint is missing, corrupt or from an incompatible run."""


def atomic_write(path: Path, write: Any) -> None:
    """Call ``write(file)`` on a temporary file, fsync it, then rename it over ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as file:
            write(file)
            file.flush()
            os.fsync(file.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    directory = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(directory)
    finally:
        os.close(directory)


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
        "learned_archive": dumps_compact(run.archives.learned),
        "vppo": run.vppo.state_dict(),
        "reward": {
            "class": f"{type(reward).__module__}.{type(reward).__qualname__}",
            "state_dict": reward.state_dict(),
            "optimizers": [opt.state_dict() for opt in run.reward_optimizers],
            "extra": reward.extra_state(),
        },
    }
    path = run.run_dir / CHECKPOINT
    # torch.save's default protocol 2 stores bytes as latin-1 text, a quarter larger.
    atomic_write(
        path, lambda file: torch.save(state, file, pickle_protocol=pickle.HIGHEST_PROTOCOL)
    )
    return path


def load_checkpoint(run: Run) -> None:
    """Restore :func:`save_checkpoint`'s state into a freshly built run of the same config.

    Raises:
        CheckpointError: if the file is missing, unreadable, of another format version, or
            was written by a run of another task or reward model.
    """
    path = run.run_dir / CHECKPOINT
    if not path.exists():
        raise CheckpointError(f"no checkpoint at {path}; the run stopped before its first one")
    try:
        state = torch.load(path, weights_only=False)  # our own file: pickled pyribs objects
    except Exception as error:
        raise CheckpointError(f"{path} is not a readable qdil checkpoint: {error}") from error
    if state.get("format") != FORMAT_VERSION:
        raise CheckpointError(
            f"{path} has format {state.get('format')!r}; this qdil reads format {FORMAT_VERSION}"
        )
    if state["task"] != run.task:
        raise CheckpointError(f"{path} belongs to a {state['task']} run, not {run.task}")
    reward_class = f"{type(run.reward).__module__}.{type(run.reward).__qualname__}"
    if state["reward"]["class"] != reward_class:
        raise CheckpointError(
            f"{path} holds a {state['reward']['class']} reward model; the config builds "
            f"{reward_class}"
        )
    run.state.iteration = state["iteration"]
    run.state.env_steps = state["env_steps"]
    run.state.seconds = state["seconds"]
    run.state.rng = np.random.default_rng()
    run.state.rng.bit_generator.state = state["rng"]
    torch.set_rng_state(state["torch_rng"])
    run.scheduler = pickle.loads(state["scheduler"])
    run.emitter = run.scheduler.emitters[0]
    run.archives.main = run.scheduler.archive
    run.archives.true = pickle.loads(state["true_archive"])
    run.archives.learned = pickle.loads(state["learned_archive"])
    run.vppo.load_state_dict(state["vppo"])
    run.reward.load_state_dict(state["reward"]["state_dict"])
    for optimizer, opt_state in zip(
        run.reward_optimizers, state["reward"]["optimizers"], strict=True
    ):
        optimizer.load_state_dict(opt_state)
    run.reward.load_extra_state(state["reward"]["extra"])


def load_archive(run_dir: str | Path, which: str = "true") -> tuple[Any, int]:
    """An archive of a run's last checkpoint: ``true``, ``learned`` or ``main`` (CMA-MAE).

    Returns:
        The pyribs archive and the iteration it was saved at.

    Raises:
        CheckpointError: if the run has no readable checkpoint.
    """
    path = Path(run_dir) / CHECKPOINT
    if not path.exists():
        raise CheckpointError(f"{run_dir}: no checkpoint at {path}")
    try:
        state = torch.load(path, weights_only=False)
    except Exception as error:
        raise CheckpointError(f"{path} is not a readable qdil checkpoint: {error}") from error
    if which == "main":
        return pickle.loads(state["scheduler"]).archive, state["iteration"]
    if which not in ("true", "learned"):
        raise ValueError(f"which must be true, learned or main, got {which!r}")
    return pickle.loads(state[f"{which}_archive"]), state["iteration"]
