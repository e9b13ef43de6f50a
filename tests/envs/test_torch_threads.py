"""Stepping the physics leaves torch's thread count as it was.

numba's OpenMP pool, launched by the first physics step of a process, sets the OpenMP
thread count that torch shares to NUMBA_NUM_THREADS (every core); once torch has read its
count, it follows. Left so, torch asked for one thread ran its small elementwise ops (tanh,
exp, sqrt) as parallel regions, at milliseconds of CPU each on a loaded machine. A fresh
process is needed: the test session started the pool already (tests/conftest.py).
"""

from __future__ import annotations

import os
import subprocess
import sys

STEP = """
import numpy as np
import torch

from qdil.envs.vector import LocomotionVectorEnv

torch.set_num_threads(1)
torch.get_num_threads()  # torch has read its count, as a run's libraries do early
env = LocomotionVectorEnv("Walker2d-v5", 48, num_threads=2)
env.reset(seed=0)  # the pool's first launch
env.step(np.zeros((48, 6)))
print(torch.get_num_threads())
"""


def test_the_physics_keeps_torchs_thread_count() -> None:
    env = {**os.environ, "NUMBA_NUM_THREADS": "2", "OMP_NUM_THREADS": "1"}
    done = subprocess.run(
        [sys.executable, "-c", STEP], env=env, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.split()[-1] == "1"
