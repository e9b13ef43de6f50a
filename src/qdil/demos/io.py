"""The qdil demonstration file: a versioned ``.npz`` readable without qdil.

:func:`save_demos` writes one (format ``qdil-demos``, version 1); :func:`load_demos` reads it
and validates it against its task; :func:`resolve_path` also finds the sets shipped with
qdil (:func:`shipped_demos`). Layout and step alignment: docs/concepts/demonstrations.md.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from qdil.demos.dataset import DemoSet
from qdil.files import atomic_write

FORMAT = "qdil-demos"
VERSION = 1
SHIPPED = "qdil.demos.shipped"
REQUIRED = (
    "obs",
    "actions",
    "contacts",
    "rewards",
    "episode_ends",
    "terminated",
    "final_obs",
    "final_contacts",
)


class DemoFormatError(ValueError):
    """A demonstration file is missing, malformed or does not fit the task."""


@dataclass(frozen=True)
class TaskShape:
    """The sizes a demonstration file must have for a task."""

    task: str
    obs_dim: int
    action_dim: int
    num_measures: int
    feet: tuple[str, ...]

    @classmethod
    def of(cls, task: str) -> TaskShape:
        """The sizes of a gymnasium task id such as ``"Walker2d-v5"``."""
        from qdil.envs import make_gymnasium_env
        from qdil.envs.tasks import make_task

        spec = type(make_task(task))  # validates the name
        env = make_gymnasium_env(spec.reference_id or spec.gym_id, quiet=True)
        return cls(
            task=task,
            obs_dim=int(env.observation_space.shape[0]),
            action_dim=int(env.action_space.shape[0]),
            num_measures=len(spec.feet),
            feet=spec.feet,
        )


def shipped_demos() -> dict[str, Path]:
    """Demonstration sets shipped with qdil, by name (``walker2d``, ``halfcheetah``, ...)."""
    folder = resources.files(SHIPPED)
    return {
        Path(entry.name).stem: Path(str(entry))
        for entry in folder.iterdir()
        if entry.name.endswith(".npz")
    }


def resolve_path(path: str | Path) -> Path:
    """A file path, or the path of a shipped set given by name (``walker2d``)."""
    candidate = Path(path)
    if candidate.exists():
        return candidate
    shipped = shipped_demos()
    if str(path) in shipped:
        return shipped[str(path)]
    names = f"shipped sets: {', '.join(sorted(shipped))}; " if shipped else ""
    raise DemoFormatError(
        f"demonstrations {path}: no such file ({names}make a set from an expert run with "
        "`qdil demos RUN_DIR --out FILE`, see docs/concepts/demonstrations.md)"
    )


def save_demos(
    demos: DemoSet, path: str | Path, qpos: np.ndarray | None = None, qvel: np.ndarray | None = None
) -> Path:
    """Write ``demos`` to ``path`` (``.npz``), atomically.

    Args:
        demos: the demonstrations.
        path: output file.
        qpos: optional (T, nq) MuJoCo positions of s_t.
        qvel: optional (T, nv) MuJoCo velocities of s_t.
    """
    ends = np.asarray(demos.episode_ends, dtype=np.int64)
    last = ends - 1
    header = {
        "format": FORMAT,
        "version": VERSION,
        "task": demos.task,
        "obs_dim": int(demos.obs.shape[1]),
        "action_dim": int(demos.actions.shape[1]),
        "num_measures": int(demos.contacts.shape[1]),
        "num_episodes": len(ends),
        "num_steps": len(demos.obs),
        "episodes": [
            {"return": float(r), "length": int(n), "measures": [float(m) for m in ms]}
            for r, n, ms in zip(demos.returns, demos.lengths, demos.measures, strict=True)
        ],
        "provenance": demos.metadata,
    }
    arrays: dict[str, np.ndarray] = {
        "header": np.array(json.dumps(header, indent=1, default=_json_default)),
        "obs": demos.obs.astype(np.float64),
        "actions": demos.actions.astype(np.float32),
        "contacts": demos.contacts.astype(np.uint8),
        "rewards": demos.rewards.astype(np.float32),
        "episode_ends": ends,
        "terminated": np.asarray(demos.terminated, dtype=bool),
        "final_obs": demos.next_obs[last].astype(np.float64),
        "final_contacts": demos.next_contacts[last].astype(np.uint8),
    }
    if qpos is not None and qvel is not None:
        arrays["qpos"], arrays["qvel"] = np.asarray(qpos, np.float64), np.asarray(qvel, np.float64)
    path = Path(path)
    atomic_write(path, lambda file: np.savez_compressed(file, **arrays))
    return path


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def read_header(path: str | Path) -> dict[str, Any]:
    """The JSON header of a demonstration file."""
    with _open(resolve_path(path)) as data:
        return _header(data, path)


def _open(path: Path) -> Any:
    try:
        return np.load(path, allow_pickle=False)
    except Exception as error:
        raise DemoFormatError(
            f"demonstrations {path}: not a readable .npz file ({error}); "
            "write demonstrations with `qdil demos` or qdil.demos.save_demos"
        ) from None


def _header(data: Any, path: str | Path) -> dict[str, Any]:
    if "header" not in data.files:
        raise DemoFormatError(f"demonstrations {path}: no 'header' entry; is it a qdil demo file?")
    try:
        header = json.loads(str(data["header"]))
    except json.JSONDecodeError as error:
        raise DemoFormatError(
            f"demonstrations {path}: the header is not valid JSON ({error})"
        ) from None
    if header.get("format") != FORMAT:
        raise DemoFormatError(
            f"demonstrations {path}: format {header.get('format')!r} is not {FORMAT!r}"
        )
    if header.get("version") != VERSION:
        raise DemoFormatError(
            f"demonstrations {path}: format version {header.get('version')!r}; this qdil reads "
            f"version {VERSION}; upgrade qdil or regenerate the file"
        )
    return header


def load_demos(
    path: str | Path, task: str | None = None, num_episodes: int | None = None
) -> DemoSet:
    """Load and validate a demonstration file.

    Args:
        path: a ``.npz`` file or the name of a shipped set (``walker2d``).
        task: the task the demonstrations must fit (sizes and id); ``None`` skips the check.
        num_episodes: keep the first n episodes.

    Raises:
        DemoFormatError: naming the file and what is wrong, and how to fix it.
    """
    resolved = resolve_path(path)
    with _open(resolved) as data:
        header = _header(data, resolved)
        missing = [name for name in REQUIRED if name not in data.files]
        if missing:
            raise DemoFormatError(f"demonstrations {resolved}: missing arrays {missing}")
        arrays = {name: np.asarray(data[name]) for name in REQUIRED}
        has_state = "qpos" in data.files
        state = {name: np.asarray(data[name]) for name in ("qpos", "qvel")} if has_state else {}
    _validate(resolved, header, arrays, task)
    ends = arrays["episode_ends"].astype(np.int64)
    if num_episodes is not None:
        if not 1 <= num_episodes <= len(ends):
            raise DemoFormatError(
                f"demonstrations {resolved}: demos.num_episodes={num_episodes}, "
                f"but the file has {len(ends)} episodes"
            )
        cut = int(ends[num_episodes - 1])
        ends = ends[:num_episodes]
        arrays = {
            k: v[:cut] if k in ("obs", "actions", "contacts", "rewards") else v[:num_episodes]
            for k, v in arrays.items()
            if k != "episode_ends"
        }
        state = {k: v[:cut] for k, v in state.items()}
    next_obs, next_contacts = _next(
        arrays["obs"], arrays["contacts"], ends, arrays["final_obs"], arrays["final_contacts"]
    )
    metadata = {
        **header.get("provenance", {}),
        "file": str(resolved),
        **({"state": state} if state else {}),
    }
    return DemoSet(
        task=header["task"],
        obs=arrays["obs"].astype(np.float64),
        actions=arrays["actions"].astype(np.float64),
        contacts=arrays["contacts"].astype(np.float32),
        rewards=arrays["rewards"].astype(np.float64),
        next_obs=next_obs.astype(np.float64),
        next_contacts=next_contacts.astype(np.float32),
        episode_ends=ends,
        terminated=arrays["terminated"].astype(bool),
        metadata=metadata,
    )


def _next(obs, contacts, ends, final_obs, final_contacts) -> tuple[np.ndarray, np.ndarray]:
    """s_{t+1} and δ(s_{t+1}) of every step from the per-step arrays and episode finals."""
    next_obs = np.roll(obs, -1, axis=0)
    next_contacts = np.roll(contacts, -1, axis=0)
    next_obs[ends - 1] = final_obs
    next_contacts[ends - 1] = final_contacts
    return next_obs, next_contacts


def _validate(path: Path, header: dict, arrays: dict[str, np.ndarray], task: str | None) -> None:
    def fail(message: str) -> None:
        raise DemoFormatError(f"demonstrations {path}: {message}")

    from qdil.envs.tasks import TASKS, VARIANTS

    # a task variant (Humanoid-v5-newton) imitates demonstrations of its gymnasium namesake
    variant = VARIANTS.get(str(task).removeprefix("qdil/"))
    namesake = variant.reference_id if variant is not None else None
    if task is not None and header.get("task") not in (task, namesake):
        fail(
            f"recorded on {header.get('task')!r}, but the run's task is {task!r}; "
            f"use demonstrations of {task} (qdil demos RUN_DIR of a {task} expert)"
        )
    if str(header.get("task")).removeprefix("qdil/") not in TASKS:
        fail(
            f"the header names task {header.get('task')!r}, which qdil does not know "
            f"(known tasks: {', '.join(TASKS)}); the file is damaged or not from qdil: "
            "regenerate it with `qdil demos`"
        )
    # the file's own sizes are checked even when no task is asked for (qdil demos --info)
    task = str(header["task"]).removeprefix("qdil/")
    obs, actions, contacts = arrays["obs"], arrays["actions"], arrays["contacts"]
    if obs.ndim != 2 or actions.ndim != 2 or contacts.ndim != 2:
        fail("obs, actions and contacts must be 2-D (steps, size)")
    steps = len(obs)
    if steps == 0:
        fail("it holds no steps")
    for name in ("actions", "contacts", "rewards"):
        if len(arrays[name]) != steps:
            fail(f"{name} has {len(arrays[name])} rows, obs has {steps}: steps are not aligned")
    # the header's sizes describe the arrays; a file where they disagree was altered
    for name, key in (("obs", "obs_dim"), ("actions", "action_dim"), ("contacts", "num_measures")):
        if key in header and arrays[name].shape[1] != header[key]:
            fail(
                f"{name} has {arrays[name].shape[1]} columns, but the header says "
                f"{key} = {header[key]}; the file is inconsistent: regenerate it with `qdil demos`"
            )
    if "num_steps" in header and header["num_steps"] != steps:
        fail(
            f"the header says num_steps = {header['num_steps']}, but obs has {steps} rows; "
            "the file is inconsistent: regenerate it with `qdil demos`"
        )
    if task is not None:
        shape = TaskShape.of(task)
        expected = {
            "obs": shape.obs_dim,
            "actions": shape.action_dim,
            "contacts": shape.num_measures,
        }
        for name, size in expected.items():
            if arrays[name].shape[1] != size:
                fail(f"{name} has {arrays[name].shape[1]} columns; {task} needs {size}")
    ends = arrays["episode_ends"]
    if ends.ndim != 1 or len(ends) == 0:
        fail("episode_ends must list at least one episode")
    if ends[-1] != steps or np.any(np.diff(np.r_[0, ends]) <= 0):
        fail(
            f"episode_ends {ends.tolist()[:8]} must increase strictly (no empty episode) "
            f"and end at {steps}"
        )
    for name in ("terminated", "final_obs", "final_contacts"):
        if len(arrays[name]) != len(ends):
            fail(f"{name} has {len(arrays[name])} rows for {len(ends)} episodes")
    if "num_episodes" in header and header["num_episodes"] != len(ends):
        fail(
            f"the header says num_episodes = {header['num_episodes']}, but episode_ends lists "
            f"{len(ends)}; the file is inconsistent: regenerate it with `qdil demos`"
        )
    for name in ("obs", "actions", "final_obs"):
        if not np.isfinite(arrays[name]).all():
            bad = np.argwhere(~np.isfinite(arrays[name]))[0].tolist()
            fail(f"{name} holds a non-finite value at {bad}")
    for name in ("contacts", "final_contacts"):
        if not np.isin(arrays[name], (0, 1)).all():
            fail(f"{name} must hold 0/1 flags")


def demo_table(demos: DemoSet) -> str:
    """The paper's demonstration table (its appendix): lengths and returns, min/max/mean/std.

    The standard deviation is the population one (ddof = 0), as the paper's table.
    """
    rows = [
        "| Task | Demo num | Attribute | min | max | mean | std |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, values in (("Length", demos.lengths.astype(float)), ("Return", demos.returns)):
        rows.append(
            f"| {demos.task} | {demos.num_episodes} | {label} | {values.min():.1f} | "
            f"{values.max():.1f} | {values.mean():.1f} | {values.std():.1f} |"
        )
    return "\n".join(rows)


def episode_summary(demos: DemoSet) -> Sequence[str]:
    """One line per episode: length, return, measures."""
    return [
        f"episode {i}: length {n}, return {r:.1f}, measures {np.round(m, 3).tolist()}"
        for i, (n, r, m) in enumerate(
            zip(demos.lengths, demos.returns, demos.measures, strict=True)
        )
    ]
