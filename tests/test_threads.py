"""``import qdil`` makes idle OpenMP threads sleep: the pools of torch and of numba's physics
kernels start with a spin count of 0, unless the user's environment chose a policy."""

from __future__ import annotations

import os
import re
import subprocess
import sys

STEP = """
import qdil, numpy as np, gymnasium, torch
venv = gymnasium.make_vec("qdil/Walker2d-v5", num_envs=4, num_threads=2)
venv.reset(seed=0)
venv.step(np.zeros((4, 6)))
torch.ones(4) @ torch.ones(4)
"""


def spin_counts(code: str, **env: str) -> list[str]:
    """``GOMP_SPINCOUNT`` of each OpenMP runtime a fresh process running ``code`` loads, as
    the runtime reports it when it starts (``OMP_DISPLAY_ENV``)."""
    environment = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    environment |= {"OMP_DISPLAY_ENV": "VERBOSE", "QDIL_NUM_THREADS": "2", **env}
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=environment, check=False
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return re.findall(r"GOMP_SPINCOUNT = '(\d+)'", done.stderr)


def test_the_physics_and_torch_pools_sleep_when_idle() -> None:
    counts = spin_counts(STEP)
    assert counts and set(counts) == {"0"}, counts  # libgomp spins 300,000 times by default


def test_a_wait_policy_the_user_set_is_kept() -> None:
    counts = spin_counts("import qdil, torch", OMP_WAIT_POLICY="ACTIVE")
    assert counts and all(int(count) > 300_000 for count in counts), counts
