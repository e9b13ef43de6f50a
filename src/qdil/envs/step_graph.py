"""A training step of the device face, recorded in one CUDA graph and replayed.

On a GPU the torch side of a training step (task formulas, episode bookkeeping, the
autoreset's choices: about 135 operators) costs more in launches than in arithmetic.
:class:`StepGraph` records a whole step, its MuJoCo Warp kernels included, in one CUDA graph
at the first call and replays it afterwards: the same kernels on the same memory, so the
results are bit-identical (``tests/test_gpu.py``). The step must keep its state in tensors
it updates in place, and read nothing from the host.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from qdil.envs.torch_step import TorchStep
from qdil.envs.warp_graphs import WarpGraphs


class StepGraph:
    """Calls ``step`` once, records it in a CUDA graph, and replays the graph after.

    Args:
        step: advances the simulations by one env step from (N, A) actions, keeping its
            state in place (no Python state may change: a replay does not run Python).
        actions: (N, A) float32 tensor of the step's actions, on the CUDA device: shape and
            dtype of every later call's.
        graphs: the Warp graphs of the physics; their sequences are launched from Python
            while the step is recorded, so that torch's graph holds their kernels.

    Each call returns new tensors (copies of the graph's outputs, which the next replay
    overwrites), as the eager step does.
    """

    def __init__(
        self,
        step: Callable[[torch.Tensor], TorchStep],
        actions: torch.Tensor,
        graphs: WarpGraphs,
    ) -> None:
        self.step, self.warp_graphs = step, graphs
        self._actions = torch.empty_like(actions)
        self._graph: torch.cuda.CUDAGraph | None = None
        self._outputs: TorchStep | None = None

    def __call__(self, actions: torch.Tensor) -> TorchStep:
        """One env step from (N, A) ``actions``: eager (and recorded) at the first call."""
        if self._graph is None:
            # the first step runs as it is (it also records the Warp graphs and loads the
            # kernels, which a capture must not do), then the same step is recorded
            result = self.step(actions)
            self._record()
            return result
        self._actions.copy_(actions)
        self._graph.replay()
        return TorchStep(*(tensor.clone() for tensor in self._outputs))

    def _record(self) -> None:
        """Record one step on a side stream; nothing runs (the kernels are only recorded)."""
        graph, stream = torch.cuda.CUDAGraph(), torch.cuda.Stream(self._actions.device)
        stream.wait_stream(torch.cuda.current_stream(self._actions.device))
        # thread_local: the capture mode Warp assumes of an external capture
        capture = torch.cuda.graph(graph, stream=stream, capture_error_mode="thread_local")
        with capture, self.warp_graphs.inlined(stream):
            self._outputs = self.step(self._actions)
        torch.cuda.current_stream(self._actions.device).wait_stream(stream)
        self._graph = graph
