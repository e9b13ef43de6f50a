"""Reward forms: the named transforms from an adversarial model's score to the reward.

A model scores a transition (GAIL's logit, AIRL's f, the WAE critic's value); its form maps
that score to the reward handed to RL, as imitation separates a discriminator from the
reward it hands on. One set of forms serves every adversarial model (``reward_form``).
What each form pays for a step and for a fall: docs/rewards/forms.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, get_args

import torch

FormName = Literal[
    "raw",
    "log1-d",
    "logd",
    "sigmoid",
    "calibrated",
    "calibrated_sigmoid",
    "standardized",
    "standardized_logit",
]
"""The names a recipe's ``reward_form`` takes."""

CALIBRATION_LOGIT = 2.0
"""|ℓ| of the expert's and the policy's mean scores under the ``calibrated`` forms."""


@dataclass(frozen=True)
class ScoreStats:
    """What the scaled forms read of the model's scores, measured after each update.

    Attributes:
        expert_mean: μ_e, the mean score of the expert transitions.
        policy_mean: μ_π, the mean score of the iteration's policy transitions.
        policy_std: σ_π, the standard deviation of the policy's scores.
        min_gap: the smallest μ_e − μ_π the calibrated forms divide by, and (over 4) the
            smallest σ_π the standardized forms divide by.
    """

    expert_mean: float
    policy_mean: float
    policy_std: float
    min_gap: float


def calibrated_logit(score: torch.Tensor, stats: ScoreStats) -> torch.Tensor:
    """Map scores onto a logit fixed by the expert's and the policy's mean scores.

    ℓ = 2·CALIBRATION_LOGIT·(s − (μ_e + μ_π)/2) / max(μ_e − μ_π, min_gap): μ_e maps to
    +CALIBRATION_LOGIT, μ_π to −CALIBRATION_LOGIT, the midpoint to 0, however far apart the
    two lie. A model that no longer separates them (gap below ``min_gap``) gives flatter
    logits instead of amplified noise.

    Args:
        score: (B,) scores.
        stats: the model's last measured statistics.

    Returns:
        (B,) logits.
    """
    gap = max(stats.expert_mean - stats.policy_mean, stats.min_gap)
    return 2.0 * CALIBRATION_LOGIT * (score - 0.5 * (stats.expert_mean + stats.policy_mean)) / gap


def standardized_logit(score: torch.Tensor, stats: ScoreStats) -> torch.Tensor:
    """Map scores onto a logit standardised on the policy's own scores.

    ℓ = (s − μ_π) / max(σ_π, min_gap/4): the policy's mean maps to 0 and every σ_π above it
    adds one logit unit, however far the expert's mean lies.

    Args:
        score: (B,) scores.
        stats: the model's last measured statistics.

    Returns:
        (B,) logits.
    """
    return (score - stats.policy_mean) / max(stats.policy_std, stats.min_gap / 4)


def log_one_minus_d(logit: torch.Tensor) -> torch.Tensor:
    """GAIL's −log(1 − σ(ℓ) + 1e-8), as the QD-IL code computes it (at most about 18.4)."""
    return -torch.log(1 - torch.sigmoid(logit) + 1e-8)


SCALES = {
    "raw": lambda score, stats: score,
    "calibrated": calibrated_logit,
    "standardized": standardized_logit,
}
OUTPUTS = {
    "raw": lambda logit: logit,
    "log1-d": log_one_minus_d,
    "logd": lambda logit: torch.log(torch.sigmoid(logit) + 1e-8),
    "sigmoid": torch.sigmoid,
}
LOWER_BOUNDS = {"raw": -math.inf, "log1-d": 0.0, "logd": math.log(1e-8), "sigmoid": 0.0}
"""The infimum of each output over all logits (what ``absorbing: fixed`` credits a fall)."""


@dataclass(frozen=True)
class RewardForm:
    """A named transform: a scale (score → logit), then an output (logit → reward).

    Attributes:
        name: the recipe's ``reward_form``.
        scale: ``raw`` (the score is the logit), ``calibrated`` or ``standardized``.
        output: ``raw`` (the logit itself), ``log1-d`` (−log(1 − σ)), ``logd`` (log σ) or
            ``sigmoid`` (σ).
        description: one line for docs and errors.
    """

    name: str
    scale: str
    output: str
    description: str

    @property
    def needs_stats(self) -> bool:
        """The form reads :class:`ScoreStats`, so the model measures them after each update."""
        return self.scale != "raw"

    @property
    def lower_bound(self) -> float:
        """The lowest reward the form can pay (−inf for a signed, unbounded form)."""
        return LOWER_BOUNDS[self.output]

    def __call__(self, score: torch.Tensor, stats: ScoreStats) -> torch.Tensor:
        """(B,) rewards from (B,) scores."""
        return OUTPUTS[self.output](SCALES[self.scale](score, stats))


FORMS = {
    form.name: form
    for form in (
        RewardForm("raw", "raw", "raw", "the score itself (a logit, AIRL's f, a critic value)"),
        RewardForm("log1-d", "raw", "log1-d", "GAIL's -log(1 - sigmoid(score)): positive"),
        RewardForm("logd", "raw", "logd", "log sigmoid(score): negative"),
        RewardForm("sigmoid", "raw", "sigmoid", "sigmoid(score): in (0, 1)"),
        RewardForm(
            "calibrated",
            "calibrated",
            "log1-d",
            "-log(1 - sigmoid(l)) of the logit calibrated on the expert and policy means",
        ),
        RewardForm(
            "calibrated_sigmoid",
            "calibrated",
            "sigmoid",
            "sigmoid(l) of the calibrated logit: in (0, 1), policy mean 0.12, expert mean 0.88",
        ),
        RewardForm(
            "standardized",
            "standardized",
            "log1-d",
            "-log(1 - sigmoid(l)) of the logit standardised on the policy's scores",
        ),
        RewardForm(
            "standardized_logit",
            "standardized",
            "raw",
            "the logit standardised on the policy's scores itself: signed",
        ),
    )
}
assert set(FORMS) == set(get_args(FormName))


def get_form(name: str) -> RewardForm:
    """The form called ``name``.

    Raises:
        ValueError: naming the unknown form and the known ones.
    """
    if name not in FORMS:
        raise ValueError(f"unknown reward_form {name!r}; the forms are: {', '.join(FORMS)}")
    return FORMS[name]
