"""``AdversarialReward``: what models trained on expert-versus-policy batches share.

Inputs are x = (s, a) or, with measure conditioning, x = (s, a, δ(s)): observations and
actions standardised with the demonstrations' statistics (the same for expert and policy
data, decision D4), the 0/1 contact flags as they are. One update is ``epochs`` passes over
the expert transitions in shuffled minibatches of ``batch_size``, each paired with as many
policy transitions drawn from the iteration's rollouts ("Discriminator Num Epochs 1" in
the paper's table). Every such model carries a gradient penalty (weight 10 by default), as
the paper applies one to all online-trained reward models. With ``absorbing`` the model also
prices the absorbing state after a termination (docs/concepts/absorbing.md).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any, Literal

import torch
import torch.nn.functional as F
from torch.optim import Optimizer
from typing_extensions import override

from qdil.data import TransitionBatch
from qdil.rewards.base import RewardModel
from qdil.rewards.nets import gradient_penalty


class AdversarialReward(RewardModel):
    """Base of GAIL, AIRL, MaxEntIRL and the WAE family.

    Subclasses take their own options and pass ``**kwargs`` on, so that these options are
    accepted by every adversarial model (and validated by the recipe parser). The default
    optimiser is one Adam over all parameters at ``learning_rate``.

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        use_measures: condition on δ(s): x = (s, a, δ(s)) (the "mC" variants).
        learning_rate: Adam learning rate (the paper: 3e-4).
        batch_size: expert (and policy) transitions per gradient step.
        epochs: passes over the expert transitions per QD iteration (the paper: 1).
        gp_weight: weight of the gradient penalty (0 disables it).
        absorbing: price the absorbing state after a termination, which the loop then
            credits where episodes terminate. ``learned`` (DAC): x gains a flag, 1 on
            absorbing transitions (copies of terminated ones), and every update adds one per
            terminated transition on either side. ``floor``: its reward is the lowest the
            model gave a policy transition after its last update (0 before the first), for
            demonstrations that never terminate. ``None``: off.
    """

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        use_measures: bool = False,
        learning_rate: float = 3e-4,
        batch_size: int = 200,
        epochs: int = 1,
        gp_weight: float = 10.0,
        absorbing: Literal["learned", "floor"] | None = None,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures)
        if batch_size < 1 or epochs < 1:
            raise ValueError(f"{type(self).__name__}: batch_size and epochs must be positive")
        if gp_weight < 0:
            raise ValueError(f"{type(self).__name__}: gp_weight must be >= 0, got {gp_weight}")
        self.use_measures = use_measures
        self.uses_measures = use_measures  # the declared need follows the option
        self.learning_rate = learning_rate
        self.batch_size = batch_size
        self.epochs = epochs
        self.gp_weight = gp_weight
        if absorbing not in (None, "learned", "floor"):
            raise ValueError(
                f"{type(self).__name__}: absorbing must be learned, floor or null, got "
                f"{absorbing!r}"
            )
        self.absorbing_mode = absorbing
        self.absorbing = absorbing is not None
        if absorbing == "floor":  # checkpointed with the model
            self.register_buffer("absorbing_floor", torch.zeros((), dtype=torch.float64))

    @property
    def input_dim(self) -> int:
        """Size of x."""
        measures = self.num_measures if self.use_measures else 0
        return self.obs_dim + self.action_dim + measures + int(self.absorbing_mode == "learned")

    def features(self, batch: TransitionBatch) -> torch.Tensor:
        """(B, input_dim) x = (s, a[, δ(s)][, absorbing]), standardised where continuous."""
        parts = [self.normalize_obs(batch.obs), self.normalize_actions(batch.actions)]
        if self.use_measures:
            parts.append(batch.contacts)
        if self.absorbing_mode == "learned":
            parts.append(batch.absorbing[:, None].to(parts[0].dtype))
        return torch.cat(parts, dim=1)

    @override
    @torch.no_grad()
    def absorbing_reward(self, batch: TransitionBatch) -> torch.Tensor:
        if not self.absorbing:
            return super().absorbing_reward(batch)
        if self.absorbing_mode == "floor":
            return torch.full_like(batch.dones, float(self.absorbing_floor))
        was_training = self.training
        self.eval()
        rewards = self.reward(batch.absorbing_copies())
        self.train(was_training)
        return rewards

    @override
    def configure_optimizers(self) -> Optimizer:
        return torch.optim.Adam(self.parameters(), lr=self.learning_rate)

    def penalty(
        self,
        critic: Callable[[torch.Tensor], torch.Tensor],
        x_e: torch.Tensor,
        x_p: torch.Tensor,
    ) -> torch.Tensor:
        """The unweighted gradient penalty of ``critic`` between expert and policy inputs.

        WGAN-GP's (:func:`~qdil.rewards.nets.gradient_penalty`); zero, and not computed,
        when ``gp_weight`` is 0.

        Args:
            critic: maps (B, d) inputs to (B,) scores.
            x_e: (B, d) expert inputs.
            x_p: (B, d) policy inputs.
        """
        return gradient_penalty(critic, x_e, x_p) if self.gp_weight else torch.zeros(())

    def descend(self, optimizer: Optimizer, loss: torch.Tensor, what: str, iteration: int) -> None:
        """One manual-optimisation step on ``loss`` (Lightning's ``manual_backward``).

        Raises:
            NonFiniteRewardError: if the loss is NaN or inf, naming ``what`` and the iteration.
        """
        self.check_finite(loss.detach(), what, iteration)
        optimizer.zero_grad()
        self.manual_backward(loss)
        optimizer.step()

    def classify(
        self,
        optimizer: Optimizer,
        logit_e: torch.Tensor,
        logit_p: torch.Tensor,
        gp: torch.Tensor,
        iteration: int,
    ) -> dict[str, float]:
        """One discriminator step: expert labelled 1, policy 0, plus the gradient penalty.

        Args:
            optimizer: the discriminator's optimiser.
            logit_e: (B,) logits of expert inputs.
            logit_p: (B,) logits of policy inputs.
            gp: the gradient penalty (unweighted).
            iteration: the QD iteration, for error messages.

        Returns:
            The step's loss, gradient penalty and accuracies on either side.
        """
        loss = F.binary_cross_entropy_with_logits(logit_e, torch.ones_like(logit_e))
        loss = loss + F.binary_cross_entropy_with_logits(logit_p, torch.zeros_like(logit_p))
        loss = loss + self.gp_weight * gp
        self.descend(optimizer, loss, "discriminator loss", iteration)
        return {
            "loss": float(loss.detach()),
            "gp": float(gp.detach()),
            "expert_acc": float((logit_e > 0).float().mean()),
            "policy_acc": float((logit_p < 0).float().mean()),
        }

    @override
    @torch.no_grad()
    def price_absorbing(self, policy: TransitionBatch) -> None:
        if self.absorbing_mode != "floor":
            return
        was_training = self.training
        self.eval()
        self.absorbing_floor.fill_(float(self.reward(policy).min()))
        self.train(was_training)

    def minibatches(
        self, expert: TransitionBatch, policy: TransitionBatch
    ) -> Iterator[tuple[TransitionBatch, TransitionBatch]]:
        """Pairs of (expert, policy) minibatches: ``epochs`` shuffled passes over the expert."""
        if len(expert) == 0 or len(policy) == 0:
            raise ValueError(f"{type(self).__name__}.update needs expert and policy transitions")
        if self.absorbing_mode == "learned":
            expert, policy = expert.with_absorbing(), policy.with_absorbing()
        size = min(self.batch_size, len(expert))
        for _ in range(self.epochs):
            order = torch.randperm(len(expert))
            for start in range(0, len(expert) - size + 1, size):
                yield expert[order[start : start + size]], policy.sample(size)


class MeasureConditioned:
    """Mixin of the "mC" models: the parent model with ``use_measures`` on by default.

    Put it first among the bases, ``class MCWAEWGAIL(MeasureConditioned, WAEWGAIL)``: the
    parent's options pass through, and x = (s, a, δ(s)) unless the recipe turns it off.

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        use_measures: measure conditioning, on by default: this is what "mC" names.
        **kwargs: the parent model's options.
    """

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        use_measures: bool = True,
        **kwargs: Any,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures, use_measures=use_measures, **kwargs)


def average(steps: list[dict[str, float]]) -> dict[str, float]:
    """Mean of per-step metrics over an update's steps."""
    return {key: sum(step[key] for step in steps) / len(steps) for key in steps[0]} if steps else {}
