"""A type checker reads the seats as protocols: both implementations of each fit them, and a
class whose member's signature differs is refused (``tests/static/seats_fit.py``)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CHECKER = shutil.which("basedpyright", path=str(Path(sys.executable).parent))
pytestmark = pytest.mark.skipif(CHECKER is None, reason="basedpyright is a dev extra")


def check(path: Path) -> subprocess.CompletedProcess[str]:
    command = [CHECKER, "--pythonpath", sys.executable, str(path)]
    return subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=300)


def test_both_implementations_of_each_seat_fit_it() -> None:
    done = check(ROOT / "tests" / "static" / "seats_fit.py")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "0 errors" in done.stdout


def test_a_member_with_another_signature_does_not_fit(tmp_path: Path) -> None:
    wrong = tmp_path / "wrong.py"
    wrong.write_text(
        "from qdil.qd import VPPO\n"
        "from qdil.seats import GradientEstimator\n\n\n"
        "class Shortcut(VPPO):\n"
        "    def walk(self, theta, stats, reward_fn, seed):  # no coefficients\n"
        "        return super().walk(theta, stats, None, reward_fn, seed)\n\n\n"
        "def seat(estimator: Shortcut) -> GradientEstimator:\n"
        "    return estimator\n"
    )
    done = check(wrong)
    assert done.returncode == 1, done.stdout
    assert '"walk" is an incompatible type' in done.stdout
