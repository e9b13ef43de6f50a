"""Foot contacts by a direct scan of MuJoCo's contact list: the reference definition.

δ_j(s) = 1 when foot geom j and the floor have a contact in MuJoCo's contact list at the
configuration of state s (``mj_kinematics`` + ``mj_collision`` at ``qpos``; within the geoms'
margin). It depends on the positions only, so contacts can be recomputed from stored states
(demonstrations, imported datasets). The batched environments compute the same flags with
MuJoCo ``contact`` sensors; tests hold the two equal.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, SupportsFloat

import gymnasium
import mujoco
import numpy as np
from typing_extensions import override


class ContactProbe:
    """Computes foot-floor contact flags for configurations of one model.

    Uses a scratch ``MjData``, so probing never disturbs a simulation in progress.

    Args:
        model: the MuJoCo model.
        feet: foot geom names, in measure order.
        floor: the floor geom name.

    Raises:
        ValueError: if a geom name is not in the model.
    """

    def __init__(self, model: mujoco.MjModel, feet: Sequence[str], floor: str = "floor") -> None:
        names = [model.geom(i).name for i in range(model.ngeom)]
        for name in (*feet, floor):
            if name not in names:
                raise ValueError(f"geom {name!r} not in the model; geoms are {names}")
        self.model = model
        self.feet = np.array([model.geom(name).id for name in feet])
        self.floor = model.geom(floor).id
        self._data = mujoco.MjData(model)

    def __call__(self, qpos: np.ndarray) -> np.ndarray:
        """(k,) float32 flags for one configuration ``qpos`` (nq,)."""
        data = self._data
        data.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, data)
        mujoco.mj_collision(self.model, data)
        return scan_contacts(data, self.feet, self.floor)

    def batch(self, qpos: np.ndarray) -> np.ndarray:
        """(T, k) float32 flags for configurations ``qpos`` (T, nq)."""
        return np.stack([self(q) for q in np.asarray(qpos, dtype=np.float64)])


def scan_contacts(data: mujoco.MjData, feet: np.ndarray, floor: int) -> np.ndarray:
    """(k,) float32 flags: foot geom ``feet[j]`` has a contact with geom ``floor`` in ``data``."""
    flags = np.zeros(len(feet), dtype=np.float32)
    for first, second in data.contact.geom[: data.ncon].tolist():
        other = second if first == floor else first if second == floor else -1
        flags[feet == other] = 1.0
    return flags


class FootContacts(gymnasium.Wrapper):
    """Adds foot-contact flags and episode statistics to a single gymnasium MuJoCo env.

    Every step and reset, ``info["foot_contact"]`` holds the (k,) flags of the new state.
    At the end of an episode (terminated, or ``horizon`` steps), ``info["episode"]`` holds
    its true return ``r``, length ``l`` and measures ``measures`` (the mean of the flags over
    the episode's steps).

    Args:
        env: a gymnasium MuJoCo env.
        feet: foot geom names, in measure order.
        floor: the floor geom name.
        horizon: the episode length at which the outer ``TimeLimit`` truncates.
    """

    def __init__(
        self, env: gymnasium.Env, feet: Sequence[str], floor: str = "floor", horizon: int = 1000
    ) -> None:
        super().__init__(env)
        self.probe = ContactProbe(env.unwrapped.model, feet, floor)
        self.horizon = horizon
        self._return = 0.0
        self._length = 0
        self._contact_sum = np.zeros(len(feet))

    def _flags(self) -> np.ndarray:
        return self.probe(self.env.unwrapped.data.qpos)

    @override
    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._return, self._length = 0.0, 0
        self._contact_sum[:] = 0.0
        return obs, {**info, "foot_contact": self._flags()}

    @override
    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        flags = self._flags()
        self._return += float(reward)
        self._length += 1
        self._contact_sum += flags
        info = {**info, "foot_contact": flags}
        if terminated or truncated or self._length >= self.horizon:
            info["episode"] = {
                "r": self._return,
                "l": self._length,
                "measures": self._contact_sum / self._length,
            }
        return obs, reward, terminated, truncated, info
