"""``render_mode="rgb_array"`` of the vector environment: frames of its first simulation.

The state (``qpos``, ``qvel``) is copied into an ``MjData`` of a copy of the model and drawn
from there, so rendering reads the batch and never writes to it: physics is bit-for-bit the
same with rendering on or off (tested). The camera follows the torso from the side, as
``qdil render`` films. MuJoCo's renderer needs OpenGL: ``MUJOCO_GL`` as set, else EGL and
then OSMesa, the first that draws (:func:`qdil.envs.gl.use_gl_backend`).
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np

RENDER_MODES = ("rgb_array",)
"""The vector environment's render modes."""

WIDTH, HEIGHT = 480, 480
"""Frame size, gymnasium's MuJoCo default."""

CAMERA_DISTANCE = {"Hopper-v5": 3.0}
"""Camera distance (m) where gymnasium's default camera is not 4 m away."""


class StateRenderer:
    """Draws states of a model from a camera that tracks the torso.

    Args:
        model: the task's model (copied; the copy's ``MjData`` is the only one written).
        width: frame width in pixels.
        height: frame height in pixels.
        distance: camera distance in metres.
    """

    def __init__(
        self, model: mujoco.MjModel, width: int = WIDTH, height: int = HEIGHT, distance: float = 4.0
    ) -> None:
        from qdil.envs.gl import use_gl_backend  # standard library only; picks EGL/OSMesa

        use_gl_backend()
        self.model = copy.copy(model)
        self.model.vis.global_.offwidth = max(self.model.vis.global_.offwidth, width)
        self.model.vis.global_.offheight = max(self.model.vis.global_.offheight, height)
        self.data = mujoco.MjData(self.model)
        self.renderer = mujoco.Renderer(self.model, height, width)
        self.camera = mujoco.MjvCamera()
        mujoco.mjv_defaultFreeCamera(self.model, self.camera)
        torso = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, "torso")
        self.camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
        self.camera.trackbodyid = torso if torso >= 0 else 1
        self.camera.distance, self.camera.elevation, self.camera.azimuth = distance, -20.0, 90.0

    def draw(self, qpos: np.ndarray, qvel: np.ndarray) -> np.ndarray:
        """One (height, width, 3) uint8 RGB frame of the state ``qpos`` (nq,), ``qvel`` (nv,)."""
        self.data.qpos[:], self.data.qvel[:] = np.asarray(qpos), np.asarray(qvel)
        mujoco.mj_forward(self.model, self.data)
        self.renderer.update_scene(self.data, camera=self.camera)
        return self.renderer.render()

    def close(self) -> None:
        """Free the OpenGL context."""
        self.renderer.close()
