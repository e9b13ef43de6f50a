"""Headless OpenGL for MuJoCo's renderer: EGL, else OSMesa, chosen by trying each.

:func:`use_gl_backend` draws one small frame with each backend in a child process and sets
``MUJOCO_GL`` to the first that works. Only the standard library is imported here, so that
a program can choose before ``mujoco`` loads. How to install one: docs/guides/videos.md.
"""

from __future__ import annotations

import functools
import importlib
import os
import subprocess
import sys

GL_PACKAGES = {"egl": "libegl1 libgl1-mesa-dri", "osmesa": "libosmesa6"}
"""The Debian packages each headless backend needs."""

# one 16×16 frame of a sphere: the whole path of a render (context, scene, read-back)
_PROBE = """
import mujoco
model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='1'/></worldbody></mujoco>")
data = mujoco.MjData(model)
mujoco.mj_forward(model, data)
renderer = mujoco.Renderer(model, 16, 16)
renderer.update_scene(data)
renderer.render()
"""


class GLUnavailableError(RuntimeError):
    """No OpenGL backend can render here; the message names the packages to install."""


def probe(backend: str, timeout: float = 120.0) -> str | None:
    """Why ``backend`` cannot render in a fresh process, or ``None`` if it can.

    Args:
        backend: a ``MUJOCO_GL`` value (``egl``, ``osmesa``, ``glfw``, ...).
        timeout: seconds the child process may take.
    """
    env = {**os.environ, "MUJOCO_GL": backend}
    if backend in GL_PACKAGES and not os.environ.get("PYOPENGL_PLATFORM"):
        env["PYOPENGL_PLATFORM"] = backend
    try:
        done = subprocess.run(
            [sys.executable, "-c", _PROBE],
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return f"no frame within {timeout:.0f} s"
    if done.returncode == 0:
        return None
    lines = [line.strip() for line in done.stderr.splitlines() if line.strip()]
    reason = lines[-1] if lines else f"exit status {done.returncode}"
    return reason if len(reason) <= 160 else reason[:159] + "…"


def _bind(backend: str) -> None:
    """Make ``backend`` the one MuJoCo's renderer uses in this process."""
    os.environ["MUJOCO_GL"] = backend
    if backend in GL_PACKAGES:
        os.environ.setdefault("PYOPENGL_PLATFORM", backend)
    if "mujoco" not in sys.modules:
        return  # mujoco reads MUJOCO_GL when it is imported
    renderer = sys.modules[sys.modules["mujoco"].Renderer.__module__]
    context = getattr(renderer, "gl_context", None)
    if context is None or getattr(context, "_MUJOCO_GL", backend) == backend:
        return
    try:
        context.GLContext = importlib.import_module(f"mujoco.{backend}").GLContext
    except (ImportError, AttributeError) as error:
        raise GLUnavailableError(
            f"mujoco was imported before MUJOCO_GL={backend} was chosen and cannot switch "
            f"({error}); start Python with MUJOCO_GL={backend} set"
        ) from None


@functools.cache
def use_gl_backend() -> str:
    """Choose the OpenGL backend of this process's renderers (once per process).

    ``MUJOCO_GL`` is used as set; unset, ``PYOPENGL_PLATFORM``'s backend is tried, or else
    ``egl`` then ``osmesa``.

    Returns:
        The backend, now in ``MUJOCO_GL``.

    Raises:
        GLUnavailableError: no candidate rendered; one line naming the Debian packages.
    """
    configured = os.environ.get("MUJOCO_GL", "").strip().lower()
    platform = os.environ.get("PYOPENGL_PLATFORM", "").strip().lower()
    if configured:
        candidates = [configured]
    elif platform in GL_PACKAGES:
        candidates = [platform]
    else:
        candidates = list(GL_PACKAGES)
    failures = []
    for backend in candidates:
        reason = probe(backend)
        if reason is None:
            _bind(backend)
            return backend
        failures.append(f"MUJOCO_GL={backend}: {reason}")
    install = " or ".join(f"{packages} ({name})" for name, packages in GL_PACKAGES.items())
    raise GLUnavailableError(
        f"no headless OpenGL to render with ({'; '.join(failures)}); install the Debian "
        f"packages {install}, e.g. `apt-get install libegl1 libgl1-mesa-dri`, or set "
        "MUJOCO_GL to a backend that works here"
    )
