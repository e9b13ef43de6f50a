"""Batched MuJoCo locomotion tasks with foot-contact measures, registered with gymnasium.

After ``import qdil``::

    venv = gymnasium.make_vec("qdil/Walker2d-v5", num_envs=64)  # LocomotionVectorEnv
    env = gymnasium.make("qdil/Walker2d-v5")                    # gymnasium's env + contacts

The vector environment steps all simulations in one multithreaded call and equals
``gymnasium.make_vec("Walker2d-v5", vectorization_mode="sync")`` step for step. The single
environment is gymnasium's own class wrapped by :class:`FootContacts`.
"""

from __future__ import annotations

from typing import Any

import gymnasium

from qdil.envs.tasks import TASKS, LocomotionTask, make_task

__all__ = [
    "TASKS",
    "ContactProbe",
    "FootContacts",
    "LocomotionTask",
    "LocomotionVectorEnv",
    "make_single_env",
    "make_task",
    "make_vector_env",
    "register_envs",
]


def make_vector_env(task: str = "Walker2d-v5", num_envs: int = 1, **kwargs: Any) -> Any:
    """Vector entry point: a :class:`LocomotionVectorEnv` (imported lazily: numba, MuJoCo)."""
    from qdil.envs.vector import LocomotionVectorEnv

    return LocomotionVectorEnv(task, num_envs, **kwargs)


def make_single_env(task: str = "Walker2d-v5", **kwargs: Any) -> gymnasium.Env:
    """Entry point: gymnasium's own env of ``task`` with :class:`FootContacts` on top."""
    from qdil.envs.contacts import FootContacts

    cls = TASKS[task]
    make_task(task, **{k: v for k, v in kwargs.items() if k != "render_mode"})  # validates
    env = gymnasium.make(cls.gym_id, max_episode_steps=-1, disable_env_checker=True, **kwargs)
    return FootContacts(env.unwrapped, cls.feet, cls.floor)


def register_envs() -> None:
    """Register ``qdil/<Task>-v5`` for every task; safe to call more than once."""
    for gym_id in TASKS:
        env_id = f"qdil/{gym_id}"
        if env_id in gymnasium.registry:
            continue
        gymnasium.register(
            id=env_id,
            entry_point=make_single_env,
            vector_entry_point=make_vector_env,
            max_episode_steps=1000,
            kwargs={"task": gym_id},
        )


def __getattr__(name: str) -> Any:
    # Heavy modules (numba kernels) load on first use, not on `import qdil`.
    if name == "LocomotionVectorEnv":
        from qdil.envs.vector import LocomotionVectorEnv

        return LocomotionVectorEnv
    if name in ("ContactProbe", "FootContacts"):
        from qdil.envs import contacts

        return getattr(contacts, name)
    raise AttributeError(name)
