"""One elite as a plain torch module: a raw observation in, the action the task executes out.

The module holds everything an elite needs outside qdil: its observation statistics and
clip, the MLP, the mean (deterministic) action, and the map from the policy's [-1, 1] to the
task's action bounds; it is what ``qdil export`` writes as ONNX or a ``torch.export`` program.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from qdil.rl.networks import VectorizedActor


class GaitPolicy(nn.Module):
    """The deterministic policy of one elite, as qdil plays it in ``qdil eval``.

    Args:
        solution: (D,) the elite's flat parameter vector.
        obs_mean: (obs_dim,) its observation mean.
        obs_var: (obs_dim,) its observation variance.
        hidden: the run's hidden widths (``policy.hidden``).
        obs_clip: the run's bound of normalised observations (``policy.obs_clip``).
        low: (A,) the task's lower action bounds.
        high: (A,) the task's upper action bounds.
    """

    def __init__(
        self,
        solution: np.ndarray,
        obs_mean: np.ndarray,
        obs_var: np.ndarray,
        hidden: tuple[int, ...],
        obs_clip: float,
        low: np.ndarray,
        high: np.ndarray,
    ) -> None:
        super().__init__()
        obs_dim, action_dim = len(obs_mean), len(low)
        actor = VectorizedActor(1, obs_dim, action_dim, hidden)
        actor.set_solutions(np.asarray(solution)[None])
        self.layers = nn.ModuleList()
        for weight, bias in zip(actor.weights, actor.biases, strict=True):
            layer = nn.Linear(weight.shape[2], weight.shape[1])
            with torch.no_grad():
                layer.weight.copy_(weight[0])
                layer.bias.copy_(bias[0])
            self.layers.append(layer)
        # float32 as qdil's sampler holds them: the scale is computed in float64 first
        mean = torch.as_tensor(obs_mean, dtype=torch.float64)
        scale = torch.sqrt(torch.as_tensor(obs_var, dtype=torch.float64) + 1e-8)
        self.register_buffer("obs_mean", mean.to(torch.float32))
        self.register_buffer("obs_scale", scale.to(torch.float32))
        self.register_buffer("obs_clip", torch.tensor(float(obs_clip)))
        self.register_buffer("low", torch.as_tensor(low, dtype=torch.float32))
        self.register_buffer("half_range", torch.as_tensor((high - low) / 2.0, dtype=torch.float32))
        self.requires_grad_(False)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """(B, obs_dim) float32 raw observations -> (B, A) float32 actions within the bounds."""
        x = ((obs - self.obs_mean) / self.obs_scale).clamp(-self.obs_clip, self.obs_clip)
        last = len(self.layers) - 1
        for i, layer in enumerate(self.layers):
            x = layer(x)
            if i < last:
                x = torch.tanh(x)
        return self.low + (x.clamp(-1.0, 1.0) + 1.0) * self.half_range

    def act(self, obs: np.ndarray) -> np.ndarray:
        """The action for a raw observation, in numpy.

        Args:
            obs: (obs_dim,) one observation, or (B, obs_dim) several.

        Returns:
            (A,) or (B, A) float32 actions within the task's bounds.
        """
        batch = torch.as_tensor(np.asarray(obs, dtype=np.float32))
        with torch.no_grad():
            actions = self(batch[None] if batch.ndim == 1 else batch).numpy()
        return actions[0] if batch.ndim == 1 else actions
