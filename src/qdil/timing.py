"""Where an iteration's time goes: named sections of the loop's parts, totalled on request.

The physics, policy inference, PPO updates, the reward model and the archives' work are
marked as sections (:func:`timed`, :func:`section`); they cost a flag check until
:func:`recording` totals them::

    with qdil.timing.recording() as seconds:
        experiment.step()
    print(seconds)  # {"physics": 1.9, "policy inference": 0.4, ...}

A section inside another of the same name counts once. ``benchmarks/bench_iteration.py``
reads its breakdown this way. :class:`Stopwatch` times the loop's own phases, the
``perf/*_seconds`` metrics of every iteration.
"""

from __future__ import annotations

import functools
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import ParamSpec, TypeVar

P = ParamSpec("P")
R = TypeVar("R")

PHYSICS = "physics"
POLICY_INFERENCE = "policy inference"
PPO_UPDATES = "PPO updates"
REWARD_MODEL = "reward model"
ARCHIVE_WORK = "archive work"
SECTIONS = (PHYSICS, POLICY_INFERENCE, PPO_UPDATES, REWARD_MODEL, ARCHIVE_WORK)
"""The sections qdil marks, in the order a breakdown lists them."""

_totals: dict[str, float] | None = None  # None: not recording
_open: set[str] = set()
_clock: Callable[[], float] = time.perf_counter


@contextmanager
def section(name: str) -> Iterator[None]:
    """Count the time inside the block under ``name`` while :func:`recording`."""
    if _totals is None or name in _open:
        yield
        return
    _open.add(name)
    start = _clock()
    try:
        yield
    finally:
        _totals[name] += _clock() - start
        _open.discard(name)


def timed(name: str) -> Callable[[Callable[P, R]], Callable[P, R]]:
    """Decorate a function or method so that its calls count under ``name``."""

    def decorate(function: Callable[P, R]) -> Callable[P, R]:
        @functools.wraps(function)
        def counted(*args: P.args, **kwargs: P.kwargs) -> R:
            if _totals is None:
                return function(*args, **kwargs)
            with section(name):
                return function(*args, **kwargs)

        return counted

    return decorate


@contextmanager
def recording(clock: Callable[[], float] = time.perf_counter) -> Iterator[dict[str, float]]:
    """Total the sections' seconds inside the block (in this process).

    Args:
        clock: what a second is: ``time.perf_counter`` (wall) or ``time.process_time``
            (this process's CPU time, for a machine other processes load).

    Yields:
        section name -> seconds, filled as the block runs.
    """
    global _totals, _clock
    if _totals is not None:
        raise RuntimeError("qdil.timing.recording() is already recording")
    _totals, _clock = defaultdict(float), clock
    try:
        yield _totals
    finally:
        _totals, _clock = None, time.perf_counter
        _open.clear()


class Stopwatch:
    """The seconds of an iteration's phases: ``with watch("walk"): ...``.

    Attributes:
        start: ``time.perf_counter()`` when the watch was made (the iteration's start).
        seconds: phase -> seconds, in the order the phases ran.
    """

    def __init__(self) -> None:
        self.start = time.perf_counter()
        self.seconds: dict[str, float] = {}

    @contextmanager
    def __call__(self, phase: str) -> Iterator[None]:
        """Time the block as ``phase``."""
        tic = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[phase] = time.perf_counter() - tic

    def metrics(self) -> dict[str, float]:
        """``perf/<phase>_seconds`` for every phase timed."""
        return {f"perf/{phase}_seconds": value for phase, value in self.seconds.items()}
