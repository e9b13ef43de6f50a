"""``AdversarialReward``: what models trained on expert-versus-policy batches share.

Inputs are x = (s, a) or, with measure conditioning, x = (s, a, δ(s)): observations and
actions standardised with the demonstrations' statistics (the same for expert and policy
data, decision D4), the 0/1 contact flags as they are. One update is ``epochs`` passes over
the expert transitions in shuffled minibatches of ``batch_size``, each paired with as many
policy transitions drawn from the iteration's rollouts ("Discriminator Num Epochs 1" in
the paper's table). Every such model carries a gradient penalty (weight 10 by default), as
the paper applies one to all online-trained reward models. Each model scores a transition;
its ``reward_form`` maps the score to the reward (:mod:`qdil.rewards.forms`). With
``absorbing`` the model also prices the absorbing state after a termination
(docs/concepts/absorbing.md).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from typing import Any, ClassVar, Literal

import torch
import torch.nn.functional as F
from torch.optim import Optimizer
from typing_extensions import override

from qdil.data import TransitionBatch
from qdil.reductions import mean_over, std_over
from qdil.rewards.base import RewardModel
from qdil.rewards.forms import CALIBRATION_LOGIT, FormName, ScoreStats, get_form
from qdil.rewards.nets import gradient_penalty

AbsorbingMode = Literal["learned", "floor", "fixed"]


class AdversarialReward(RewardModel):
    """Base of GAIL, AIRL, MaxEntIRL and the WAE family.

    Subclasses take their own options and pass ``**kwargs`` on, so that these options are
    accepted by every adversarial model (and validated by the recipe parser). A subclass
    defines :meth:`score` and :meth:`update`; the reward is its form of the score. The
    default optimiser is one Adam over all parameters at ``learning_rate``.

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k.
        use_measures: condition on δ(s): x = (s, a, δ(s)) (the "mC" variants).
        feature_clip: bound of the standardised observations and actions in x, as the
            policy clips its own (``policy.obs_clip``). Features the demonstrations hold
            constant (std floored at 1e-3: Humanoid's contact forces on every body but the
            feet) standardise to thousands when a policy falls; ``None``: unbounded.
        learning_rate: Adam learning rate (the paper: 3e-4).
        batch_size: expert (and policy) transitions per gradient step.
        epochs: passes over the expert transitions per QD iteration (the paper: 1).
        steps_per_update: when set, each update takes exactly this many minibatch steps
            (passes over fresh shuffles of the expert transitions, the last one cut short)
            in place of ``epochs`` passes; the critic's cadence, independent of how many
            demonstrations there are. ``None``: ``epochs`` passes.
        gp_weight: weight of the gradient penalty (0 disables it).
        reward_form: the transform from score to reward (:data:`qdil.rewards.forms.FORMS`);
            ``None``: the model's own (``default_form``).
        min_gap: smallest expert–policy score gap the ``calibrated`` forms divide by, and
            (over 4) the smallest policy spread the ``standardized`` forms divide by.
        calibration_samples: policy transitions (at most) scored after each update to
            measure the statistics the scaled forms read; all expert transitions are scored.
        absorbing: price the absorbing state after a termination, which the loop then
            credits where episodes terminate. ``learned`` (DAC): x gains a flag, 1 on
            absorbing transitions (copies of terminated ones), and every update adds one per
            terminated transition on either side. ``floor``: its reward is the lowest the
            model gave a policy transition after its last update (0 before the first), for
            demonstrations that never terminate. ``fixed``: its reward is the form's lower
            bound r_min, so a true termination is worth r_min/(1 − γ) (LS-IQ); a form
            bounded below only. ``None``: off.

    Attributes:
        default_form: the form a model uses when the recipe names none.
        always_measures: measure (and log) the score statistics after every update, even
            for a form that does not read them.
    """

    default_form: ClassVar[FormName] = "raw"
    always_measures: ClassVar[bool] = False

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        num_measures: int,
        *,
        use_measures: bool = False,
        feature_clip: float | None = None,
        learning_rate: float = 3e-4,
        batch_size: int = 200,
        epochs: int = 1,
        steps_per_update: int | None = None,
        gp_weight: float = 10.0,
        reward_form: FormName | None = None,
        min_gap: float = 1.0,
        calibration_samples: int = 8192,
        absorbing: AbsorbingMode | None = None,
    ) -> None:
        super().__init__(obs_dim, action_dim, num_measures)
        name = type(self).__name__
        if batch_size < 1 or epochs < 1:
            raise ValueError(f"{name}: batch_size and epochs must be positive")
        if steps_per_update is not None and steps_per_update < 1:
            raise ValueError(f"{name}: steps_per_update must be positive or null")
        if gp_weight < 0:
            raise ValueError(f"{name}: gp_weight must be >= 0, got {gp_weight}")
        if feature_clip is not None and not feature_clip > 0:
            raise ValueError(f"{name}: feature_clip must be > 0 or null, got {feature_clip}")
        if min_gap <= 0:
            raise ValueError(f"{name}: min_gap must be > 0, got {min_gap}")
        if calibration_samples < 1:
            raise ValueError(f"{name}: calibration_samples must be positive")
        if reward_form is not None and type(self).reward is not AdversarialReward.reward:
            raise ValueError(
                f"{name} computes its own reward, so reward_form does not apply to it; "
                "leave reward.init_args.reward_form out"
            )
        self.form = get_form(reward_form or self.default_form)
        if absorbing not in (None, "learned", "floor", "fixed"):
            raise ValueError(
                f"{name}: absorbing must be learned, floor, fixed or null, got {absorbing!r}"
            )
        if absorbing == "fixed" and not math.isfinite(self.form.lower_bound):
            raise ValueError(
                f"{name}: absorbing: fixed credits a fall the form's lowest reward, and "
                f"reward_form {self.form.name!r} has none; choose a form bounded below "
                "(sigmoid, log1-d, calibrated, calibrated_sigmoid, standardized, logd)"
            )
        self.use_measures = use_measures
        self.feature_clip = feature_clip
        self.learning_rate = learning_rate
        self.batch_size = batch_size
        self.epochs = epochs
        self.steps_per_update = steps_per_update
        self.gp_weight = gp_weight
        self.min_gap = min_gap
        self.calibration_samples = calibration_samples
        self.absorbing = absorbing
        if absorbing == "floor":  # checkpointed with the model
            self.register_buffer("absorbing_floor", torch.zeros((), dtype=torch.float64))
        # μ_e and μ_π of the last update (checkpointed); the initial pair (+2, −2) makes the
        # calibrated logit the untrained model's own score
        self.register_buffer(
            "critic_means",
            torch.tensor([CALIBRATION_LOGIT, -CALIBRATION_LOGIT], dtype=torch.float64),
        )
        # σ_π of the last update (checkpointed; 1 before the first)
        self.register_buffer("critic_policy_std", torch.ones((), dtype=torch.float64))
        self._register_load_state_dict_pre_hook(_default_stats)

    @property
    def input_dim(self) -> int:
        """Size of x."""
        measures = self.num_measures if self.use_measures else 0
        return self.obs_dim + self.action_dim + measures + int(self.absorbing == "learned")

    def features(self, batch: TransitionBatch) -> torch.Tensor:
        """(B, input_dim) x = (s, a[, δ(s)][, absorbing]), standardised where continuous."""
        parts = [self.normalize_obs(batch.obs), self.normalize_actions(batch.actions)]
        if self.feature_clip is not None:
            parts = [part.clamp(-self.feature_clip, self.feature_clip) for part in parts]
        if self.use_measures:
            parts.append(batch.contacts)
        if self.absorbing == "learned":
            parts.append(batch.absorbing[:, None].to(parts[0].dtype))
        return torch.cat(parts, dim=1)

    def score(self, batch: TransitionBatch) -> torch.Tensor:
        """(B,) the model's score of each transition, higher where it looks like the expert's."""
        raise NotImplementedError(f"{type(self).__name__} must define score(batch)")

    @property
    def stats(self) -> ScoreStats:
        """The score statistics of the last update, as the scaled forms read them."""
        expert_mean, policy_mean = self.critic_means.tolist()
        return ScoreStats(expert_mean, policy_mean, float(self.critic_policy_std), self.min_gap)

    @override
    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        return self.form(self.score(batch), self.stats)

    @torch.no_grad()
    def measure(self, expert: TransitionBatch, policy: TransitionBatch) -> dict[str, float]:
        """Store the score statistics after an update, where the form (or the model) wants them.

        Args:
            expert: every expert transition (all are scored).
            policy: the iteration's policy transitions (a random subset is scored).

        Returns:
            μ_e, μ_π, the standard deviation on either side and, for a scaled form, the mean
            reward on either side, to log (``critic_*``, ``reward_*``); empty when nothing
            was measured.
        """
        if not (self.form.needs_stats or self.always_measures):
            return {}
        if len(policy) > self.calibration_samples:
            policy = policy[torch.randperm(len(policy))[: self.calibration_samples]]
        scores = self.score(expert), self.score(policy)
        # every expert transition: from 32,768 of them torch's mean would split by thread
        means = [float(mean_over(s, 0)) for s in scores]
        self.critic_means.copy_(torch.tensor(means, dtype=torch.float64))
        if len(scores[1]) > 1:
            self.critic_policy_std.fill_(float(std_over(scores[1], 0)))
        metrics = {"critic_expert": means[0], "critic_policy": means[1]}
        # the spread within each side, against the gap: how much a calibrated form can tell
        # policy transitions apart
        metrics["critic_expert_std"], metrics["critic_policy_std"] = (
            float(std_over(s, 0)) if len(s) > 1 else 0.0 for s in scores
        )
        if self.form.needs_stats:  # from the scores at hand, no second pass
            metrics["reward_expert"] = float(self.form(scores[0], self.stats).mean())
            metrics["reward_policy"] = float(self.form(scores[1], self.stats).mean())
        return metrics

    @override
    @torch.no_grad()
    def absorbing_reward(self, batch: TransitionBatch) -> torch.Tensor:
        if not self.absorbing:
            return super().absorbing_reward(batch)
        if self.absorbing == "fixed":
            return torch.full_like(batch.dones, self.form.lower_bound)
        if self.absorbing == "floor":
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
        if self.absorbing != "floor":
            return
        was_training = self.training
        self.eval()
        self.absorbing_floor.fill_(float(self.reward(policy).min()))
        self.train(was_training)

    def minibatches(
        self, expert: TransitionBatch, policy: TransitionBatch
    ) -> Iterator[tuple[TransitionBatch, TransitionBatch]]:
        """Pairs of (expert, policy) minibatches over shuffled passes of the expert.

        ``epochs`` whole passes, or exactly ``steps_per_update`` minibatches when it is set.
        """
        if len(expert) == 0 or len(policy) == 0:
            raise ValueError(f"{type(self).__name__}.update needs expert and policy transitions")
        if self.absorbing == "learned":
            expert, policy = expert.with_absorbing(), policy.with_absorbing()
        size = min(self.batch_size, len(expert))
        steps = self.steps_per_update or self.epochs * (len(expert) // size)
        taken = 0
        while taken < steps:
            order = torch.randperm(len(expert))
            for start in range(0, len(expert) - size + 1, size):
                if taken == steps:
                    return
                yield expert[order[start : start + size]], policy.sample(size)
                taken += 1


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


def _default_stats(state_dict: dict[str, Any], prefix: str, *_: Any) -> None:
    """Load checkpoints written before the score statistics were kept (as first set)."""
    state_dict.setdefault(
        prefix + "critic_means",
        torch.tensor([CALIBRATION_LOGIT, -CALIBRATION_LOGIT], dtype=torch.float64),
    )
    state_dict.setdefault(prefix + "critic_policy_std", torch.ones((), dtype=torch.float64))


def average(steps: list[dict[str, float]]) -> dict[str, float]:
    """Mean of per-step metrics over an update's steps."""
    return {key: sum(step[key] for step in steps) / len(steps) for key in steps[0]} if steps else {}
