"""``RewardModel``: the contract between reward plugins and the QD loop.

A reward model is a LightningModule with manual optimisation that the QD loop calls itself
(never ``Trainer.fit``): :meth:`RewardModel.setup` once, then :meth:`RewardModel.predict_reward`
and :meth:`RewardModel.update` every iteration; class flags declare what it needs. Lifecycle
and rules: docs/rewards/index.md (section "The contract").
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import lightning as L
import torch

from qdil.data import Rollout, TransitionBatch
from qdil.demos.dataset import DemoSet


class NonFiniteRewardError(RuntimeError):
    """A reward model produced NaN or inf rewards or losses."""


class RewardContractError(TypeError):
    """A reward model class lacks a method of the contract that the QD loop calls."""


# What the QD loop calls on every model, and on learned models (``learned = True``) besides;
# each with the signature a message shows.
REQUIRED_METHODS = {"reward": "reward(batch)"}
REQUIRED_WHEN_LEARNED = {
    "configure_optimizers": "configure_optimizers()",
    "update": "update(expert, policy, iteration)",
}


def missing_methods(cls: type[RewardModel]) -> list[str]:
    """Signatures of the contract's methods that ``cls`` inherits unimplemented.

    Args:
        cls: a :class:`RewardModel` subclass.

    Returns:
        ``reward(batch)`` if it is missing, and for a learned model ``configure_optimizers()``
        and ``update(...)`` if they are missing; empty when the class is complete.
    """
    required = dict(REQUIRED_METHODS)
    if cls.learned:
        required |= REQUIRED_WHEN_LEARNED
    # the base versions only raise (reward), return nothing (Lightning's configure_optimizers)
    # or train nothing (update), so inheriting one of them means it was never written
    defaults = {
        "reward": RewardModel,
        "update": RewardModel,
        "configure_optimizers": L.LightningModule,
    }
    return [
        signature
        for method, signature in required.items()
        if getattr(cls, method) is getattr(defaults[method], method)
    ]


def model_label(cls: type[RewardModel]) -> str:
    """``name (module.Class)``, or ``module.Class`` for an unregistered class: what to open."""
    path = f"{cls.__module__}.{cls.__qualname__}"
    return f"{cls.name} ({path})" if cls.name else path


def check_demos(model: RewardModel | type[RewardModel], path: str | Path | None) -> None:
    """Refuse a reward model (an instance or its class) that needs demonstrations, without any.

    Raises:
        ValueError: naming ``demos.path`` and the model.
    """
    if model.needs_demos and path is None:
        cls = model if isinstance(model, type) else type(model)
        label = model.name or cls.__name__
        raise ValueError(f"demos.path: the {label} reward model needs demonstrations")


def check_contract(cls: type[RewardModel]) -> None:
    """Refuse a reward model class that lacks a method of the contract, before training.

    Raises:
        RewardContractError: naming the class, its module and the missing methods.
    """
    missing = missing_methods(cls)
    if not missing:
        return
    learned = [m for m in missing if m not in REQUIRED_METHODS.values()]
    advice = "implement it" if len(missing) == 1 else "implement them"
    if learned:  # a fixed reward needs neither an optimiser nor an update
        advice += ", or set learned = False for a reward that is not trained online"
    raise RewardContractError(
        f"reward model {model_label(cls)} does not implement {' and '.join(missing)}; {advice} "
        "(the contract: docs/rewards/index.md#the-contract)"
    )


class RewardModel(L.LightningModule):
    """Base class of every reward model (built-in or plugin).

    Args:
        obs_dim: observation size.
        action_dim: action size.
        num_measures: k, the number of foot-contact flags in δ(s).

    Attributes:
        name: registry key (set by :func:`qdil.rewards.register_reward`).
        description: one line shown by ``qdil rewards list``.
        learned: ``update`` trains the model online (False for fixed rewards).
        needs_demos: ``setup`` needs demonstrations.
        use_measures: the reward reads δ(s) (measure conditioning); an option of the
            adversarial models and GIRIL.
        needs_next_obs: the reward reads s_{t+1}.
        needs_log_probs: the update reads the policy's log-probabilities (AIRL).
        is_true_reward: the rewards are exactly the task's true rewards.
        prefers_expert: the reward is higher on expert-like transitions (True for
            imitation rewards; False for curiosity rewards such as GIRIL's; None when it
            does not compare, as the true reward). The contract tests check it.
        absorbing: how the model prices the absorbing state after a termination
            (:meth:`absorbing_reward`; ``learned``, ``floor`` or ``fixed``), where the loop
            then adds that state's worth; ``None``: off. An option of the adversarial models.
    """

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    learned: ClassVar[bool] = True
    needs_demos: ClassVar[bool] = True
    use_measures: bool = False
    needs_next_obs: ClassVar[bool] = False
    needs_log_probs: ClassVar[bool] = False
    is_true_reward: ClassVar[bool] = False
    prefers_expert: ClassVar[bool | None] = True
    absorbing: str | None = None

    def __init__(self, obs_dim: int, action_dim: int, num_measures: int) -> None:
        super().__init__()
        check_contract(type(self))  # before any training, not at the first missing call
        for label, value in (
            ("obs_dim", obs_dim),
            ("action_dim", action_dim),
            ("num_measures", num_measures),
        ):
            if int(value) < 1:
                raise ValueError(f"{type(self).__name__}: {label} must be positive, got {value}")
        self.automatic_optimization = False
        self.obs_dim, self.action_dim, self.num_measures = (
            int(obs_dim),
            int(action_dim),
            int(num_measures),
        )
        # input normalisation shared by expert and policy data (decision D4), fit in setup()
        self.register_buffer("obs_mean", torch.zeros(self.obs_dim))
        self.register_buffer("obs_std", torch.ones(self.obs_dim))
        self.register_buffer("action_mean", torch.zeros(self.action_dim))
        self.register_buffer("action_std", torch.ones(self.action_dim))

    # -------------------------------------------------------------- lifecycle
    def setup(self, demos: DemoSet | None) -> None:  # type: ignore[override]
        """Fit the input normalisation on the demonstrations; subclasses extend it.

        Args:
            demos: the expert demonstrations, or ``None`` when ``needs_demos`` is False.
        """
        if demos is None:
            return
        batch = demos.transitions()
        self.obs_mean.copy_(batch.obs.mean(0))
        self.obs_std.copy_(batch.obs.std(0).clamp_min(1e-3))
        self.action_mean.copy_(batch.actions.mean(0))
        self.action_std.copy_(batch.actions.std(0).clamp_min(1e-3))

    def pretrain(self, demos: DemoSet | None) -> None:
        """Offline fitting on the demonstrations, once, after :meth:`setup` (default: none).

        Not called when a run resumes from a checkpoint, which restores its result.
        """

    def reward(self, batch: TransitionBatch) -> torch.Tensor:
        """(B,) differentiable reward of transitions; what :meth:`update` trains."""
        raise NotImplementedError(f"{type(self).__name__} must implement reward(batch)")

    def update(
        self, expert: TransitionBatch | None, policy: TransitionBatch, iteration: int
    ) -> dict[str, float]:
        """One reward-model update per QD iteration; returns metrics to log.

        Called every iteration for every model; fixed rewards return ``{}``.

        Args:
            expert: expert transitions from the demonstrations (``None`` when the model
                declares ``needs_demos = False``).
            policy: transitions of the current search policy from this iteration.
            iteration: the QD iteration (Lightning's ``global_step`` is 0 under Fabric).
        """
        return {}

    @torch.no_grad()
    def predict_reward(self, rollout: Rollout, *, update: bool = False) -> torch.Tensor:
        """(T, N) per-step rewards for RL, without gradients.

        Args:
            rollout: time-major transitions.
            update: the rollout is a training rollout whose visits count (the exploration
                bonus counts them); False for evaluation episodes.
        """
        was_training = self.training
        self.eval()
        rewards = self.reward(rollout.flat()).reshape(rollout.rewards.shape)
        self.train(was_training)
        return rewards

    # ----------------------------------------------------------------- helpers
    def normalize_obs(self, obs: torch.Tensor) -> torch.Tensor:
        """Observations standardised with the demonstrations' statistics."""
        return (obs - self.obs_mean) / self.obs_std

    def normalize_actions(self, actions: torch.Tensor) -> torch.Tensor:
        """Actions standardised with the demonstrations' statistics."""
        return (actions - self.action_mean) / self.action_std

    def check_finite(self, value: torch.Tensor, what: str, iteration: int) -> None:
        """Raise :class:`NonFiniteRewardError` naming the model, the value and the iteration.

        The message's advice depends on where the values came from: a model trained online
        may have diverged, while a fixed one (or a learned one before its first update) computes
        them in ``reward()`` from its inputs and what ``setup``/``pretrain`` fitted.
        """
        finite = torch.isfinite(value)
        if finite.all():
            return
        nan = int(torch.isnan(value).sum())
        inf = int((~finite).sum()) - nan
        kinds = " and ".join(f"{n} {kind}" for n, kind in ((nan, "NaN"), (inf, "inf")) if n)
        count = f"{kinds} among {value.numel()} values"
        if not self.learned:
            advice = (
                "it is not trained online, so check reward() and what setup()/pretrain() fit "
                "on the demonstrations (a division by a zero std, the log of 0, NaN inputs)"
            )
        elif what == "rewards" and iteration <= 1:
            advice = (
                "this is before its first update, so check reward() and setup() on the "
                "demonstrations (a division by a zero std, the log of 0, NaN inputs)"
            )
        else:
            advice = (
                "its training diverged: lower its learning rate or raise its gradient "
                "penalty (metrics.csv holds its reward/* metrics of the iterations before)"
            )
        raise NonFiniteRewardError(
            f"reward model {model_label(type(self))}: non-finite {what} at QD iteration "
            f"{iteration} ({count}); {advice}"
        )

    def absorbing_reward(self, batch: TransitionBatch) -> torch.Tensor:
        """(B,) per-step rewards of the absorbing state entered from each transition.

        Only for a model with ``absorbing`` on; the loop calls it on the terminated
        transitions of each rollout and adds that state's worth there
        (docs/concepts/absorbing.md).
        """
        raise NotImplementedError(
            f"reward model {model_label(type(self))} does not price an absorbing state; the "
            "adversarial models do (reward.init_args.absorbing: learned, floor or fixed)"
        )

    def price_absorbing(self, policy: TransitionBatch) -> None:
        """Set the absorbing state's price from the iteration's policy transitions.

        Called after each update of a model with ``absorbing`` on (default: nothing to do).
        """

    def extra_state(self) -> dict[str, Any]:
        """State beyond ``state_dict`` (counters, pools) for checkpoints."""
        return {}

    def load_extra_state(self, state: dict[str, Any]) -> None:
        """Restore :meth:`extra_state`."""
