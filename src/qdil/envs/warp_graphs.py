"""Fixed sequences of MuJoCo Warp launches, recorded in Warp graphs and replayed.

A MuJoCo Warp step is hundreds of kernel launches, and launching them from Python costs far
more than the physics they run. :class:`WarpGraphs` records each fixed sequence (a frame skip
of steps, the sensor pass, a reset) at its first call and replays it afterwards: one launch
instead of hundreds, the same kernels on the same arrays, so results are bit-identical.
Inside a CUDA graph that torch records (:mod:`qdil.envs.step_graph`), the sequences are
launched from Python instead, so that the outer graph holds their kernels.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any

import torch


class WarpGraphs:
    """The Warp graphs of one device's fixed launch sequences, by key.

    Args:
        warp: the ``warp`` module.
        device: Warp's name of the device (``"cpu"``, ``"cuda"``, ``"cuda:N"``).
        enabled: record and replay; ``False`` launches every sequence from Python.

    Attributes:
        recorded: the graph of each key launched so far; ``None`` where one could not be
            recorded (those sequences are launched from Python).
        enabled: whether sequences are recorded (a test may switch it off).
        outer_stream: while torch records a CUDA graph of whole steps (:meth:`inlined`),
            the Warp stream every launch must go to; ``None`` otherwise.
    """

    def __init__(self, warp: Any, device: str, enabled: bool = True) -> None:
        self.warp, self.device, self.enabled = warp, device, enabled
        self.recorded: dict[tuple, Any] = {}
        self.outer_stream: Any = None  # the Warp stream of a capture torch records
        # a CUDA graph cannot be recorded on torch's legacy default stream: record on one
        # of Warp's and replay on torch's (the CPU device records without a stream)
        self._stream = warp.Stream(device) if device.startswith("cuda") else None

    def launch(self, key: tuple, launches: Callable[[], None]) -> None:
        """Run ``launches`` (Warp launches on fixed arrays only), from a graph after the first.

        The first call launches them one by one (Warp compiles and loads their modules) and
        records them in a graph without running them again; later calls replay the graph on
        the current stream (torch's, see ``WarpBatch._on_torch_stream``).
        """
        if self.outer_stream is not None:  # inside torch's capture: its graph takes them
            launches()
            return
        graph = self.recorded.get(key)
        if graph is not None:
            self.warp.capture_launch(graph)
            return
        launches()
        if not self.enabled or key in self.recorded:  # a None entry: it could not be recorded
            return
        try:
            on_stream = self._stream is not None
            with self.warp.ScopedStream(self._stream) if on_stream else contextlib.nullcontext():
                capture = self.warp.ScopedCapture(device=self.device)
                with capture:
                    launches()
            self.recorded[key] = capture.graph
        except RuntimeError:  # a launch that cannot be recorded: launch it from Python
            self.recorded[key] = None

    @contextlib.contextmanager
    def inlined(self, stream: torch.cuda.Stream) -> Iterator[None]:
        """Launch every sequence from Python, into a CUDA graph torch records on ``stream``.

        Warp learns of the capture (``external=True``) on the one Warp stream of ``stream``
        that every launch meanwhile uses (:attr:`outer_stream`), so that its conditional
        nodes (MuJoCo Warp's ``capture_if``) join torch's graph instead of reading the
        device.
        """
        warp_stream = self.warp.stream_from_torch(stream)
        capture = self.warp.ScopedCapture(stream=warp_stream, external=True)
        self.outer_stream = warp_stream
        try:
            with capture:
                yield
        finally:
            self.outer_stream = None
