"""Batched MuJoCo locomotion tasks with foot-contact measures, registered with gymnasium.

After ``import qdil``::

    venv = gymnasium.make_vec("qdil/Walker2d-v5", num_envs=64)  # LocomotionVectorEnv
    env = gymnasium.make("qdil/Walker2d-v5")                    # gymnasium's env + contacts

The vector environment steps all simulations in one multithreaded call and equals
``gymnasium.make_vec("Walker2d-v5", vectorization_mode="sync")`` step for step. The single
environment is gymnasium's own class wrapped by :class:`FootContacts`.
"""

from __future__ import annotations

import warnings
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
    env = make_gymnasium_env(cls.gym_id, max_episode_steps=-1, disable_env_checker=True, **kwargs)
    return FootContacts(env.unwrapped, cls.feet, cls.floor)


def make_gymnasium_env(gym_id: str, *, quiet: bool = False, **kwargs: Any) -> gymnasium.Env:
    """``gymnasium.make(gym_id, **kwargs)`` with MuJoCo's compiler warnings as Python warnings.

    MuJoCo's default warning handler appends to ``MUJOCO_LOG.TXT`` in the working directory
    (half_cheetah.xml's deprecated ``settotalmass`` triggers it on every load), which would
    litter the user's folder. The handler is replaced only while the model loads.

    Args:
        gym_id: a gymnasium task id such as ``"HalfCheetah-v5"``.
        quiet: drop the warnings instead, for internal uses (sizes, contact replay) where
            a warning about gymnasium's own model file would only be noise.
        **kwargs: passed to ``gymnasium.make``.
    """
    import mujoco

    messages: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(messages.append)  # nothing may raise inside MuJoCo's C code
    try:
        env = gymnasium.make(gym_id, **kwargs)
    finally:
        mujoco.set_mju_user_warning(previous)
    for message in [] if quiet else messages:
        warnings.warn(f"MuJoCo: {message}", UserWarning, stacklevel=2)
    return env


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
