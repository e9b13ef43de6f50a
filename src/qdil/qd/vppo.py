"""VPPO: PPGA's vectorised PPO, the gradient estimator and the walk of the search policy.

Reads top to bottom (CleanRL style): :meth:`VPPO.compute_jacobian` trains k+1 copies of
θ_μ side by side, :meth:`VPPO.walk` moves θ_μ, both with the same PPO update
(:func:`qdil.rl.ppo.ppo_update`, its settings one object, ``self.ppo``); the run's executor
steps the simulations. It fills the loop's :class:`~qdil.seats.GradientEstimator` seat.
Why each detail is as it is: ``docs/concepts/vppo.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import torch

from qdil.rl.collect import RewardFn
from qdil.rl.networks import VectorizedActor, VectorizedCritic
from qdil.rl.normalize import RunningMeanStd
from qdil.rl.ppo import PPOSettings, ppo_update
from qdil.seats import PhaseResult

if TYPE_CHECKING:
    from qdil.config import PolicyConfig
    from qdil.envs.vector import LocomotionVectorEnv
    from qdil.executors.base import Executor

# each phase's critic, its optimiser and return statistics: they persist across QD
# iterations and restarts (checkpointed beside the noise generator)
_PERSISTENT = tuple(
    f"{p}_{x}" for p in ("jacobian", "walk") for x in ("critic", "critic_opt", "returns")
)


class VPPO:
    """PPGA's gradient estimator and search-policy walk (paper Alg. 1, lines 4 and 16).

    Defaults are the paper's (PPGA's Walker2d hyperparameters).

    Args:
        rollout_length: steps per environment per PPO iteration.
        jacobian_iterations: N1, PPO iterations of the k+1 copies.
        walk_iterations: N2, PPO iterations of the walk.
        num_minibatches: minibatches per epoch.
        update_epochs: epochs per PPO iteration.
        learning_rate: Adam learning rate of actors and critics.
        adam_eps: Adam epsilon.
        gamma: discount.
        gae_lambda: GAE λ.
        clip_coef: PPO ratio clip.
        value_clip: value-loss clip (``None`` for an unclipped value loss).
        vf_coef: value-loss weight.
        ent_coef: entropy bonus weight.
        max_grad_norm: per-policy gradient-norm clip.
        target_kl: stop the epochs once the mean approximate KL exceeds it (``None``: never).
        normalize_returns: learn normalised value targets.
        adaptive_std: learn the log standard deviations (PPGA: False for Walker2d and
            Humanoid, True for HalfCheetah).
        bootstrap_truncation: bootstrap time-limit truncations from the final state.
        critic_hidden: critic widths (paper: 256, 256).
    """

    def __init__(
        self,
        rollout_length: int = 128,
        jacobian_iterations: int = 10,
        walk_iterations: int = 10,
        num_minibatches: int = 8,
        update_epochs: int = 4,
        learning_rate: float = 1e-3,
        adam_eps: float = 1e-5,
        gamma: float = 0.99,
        gae_lambda: float = 0.95,
        clip_coef: float = 0.2,
        value_clip: float | None = 0.2,
        vf_coef: float = 2.0,
        ent_coef: float = 0.0,
        max_grad_norm: float = 1.0,
        target_kl: float | None = 0.008,
        normalize_returns: bool = True,
        adaptive_std: bool = False,
        bootstrap_truncation: bool = True,
        critic_hidden: Sequence[int] = (256, 256),
    ) -> None:
        for name, value in (
            ("rollout_length", rollout_length),
            ("jacobian_iterations", jacobian_iterations),
            ("walk_iterations", walk_iterations),
            ("num_minibatches", num_minibatches),
            ("update_epochs", update_epochs),
        ):
            if value < 1:
                raise ValueError(f"rl.{name} must be at least 1, got {value}")
        self.rollout_length = rollout_length
        self.jacobian_iterations = jacobian_iterations
        self.walk_iterations = walk_iterations
        self.num_minibatches = num_minibatches
        self.update_epochs = update_epochs
        self.learning_rate = learning_rate
        self.adam_eps = adam_eps
        self.gamma = gamma
        self.gae_lambda = gae_lambda
        self.clip_coef = clip_coef
        self.value_clip = value_clip
        self.vf_coef = vf_coef
        self.ent_coef = ent_coef
        self.max_grad_norm = max_grad_norm
        self.target_kl = target_kl
        self.normalize_returns = normalize_returns
        self.adaptive_std = adaptive_std
        self.bootstrap_truncation = bootstrap_truncation
        self.critic_hidden = tuple(critic_hidden)
        # what one PPO iteration reads, in one object (the learning rate builds the optimisers)
        self.ppo = PPOSettings(
            gamma=gamma,
            gae_lambda=gae_lambda,
            num_minibatches=num_minibatches,
            update_epochs=update_epochs,
            clip_coef=clip_coef,
            value_clip=value_clip,
            vf_coef=vf_coef,
            ent_coef=ent_coef,
            max_grad_norm=max_grad_norm,
            target_kl=target_kl,
            normalize_returns=normalize_returns,
            bootstrap_truncation=bootstrap_truncation,
        )

    # ------------------------------------------------------------------ setup
    def setup(
        self,
        train_env: LocomotionVectorEnv,
        executor: Executor,
        policy: PolicyConfig,
        generator: torch.Generator,
        seed: int,
    ) -> None:
        """Bind the training simulations and the run's executor; build the persistent critics.

        The policies, critics, statistics and rollouts live on the physics' device,
        ``train_env.device``.

        Args:
            train_env: ``SAME_STEP`` environment of the PPO phases; its N must be divisible
                by k+1.
            executor: steps the simulations (set up by the run).
            policy: the run's policy family (hidden widths).
            generator: the run's action noise, on ``train_env.device``.
            seed: seed of the critics' initialisation.

        Raises:
            ValueError: if N is not divisible by k+1, or the environment does not autoreset
                on the same step.
        """
        num_objectives = train_env.num_feet + 1
        if train_env.num_envs % num_objectives:
            raise ValueError(
                f"env.num_envs={train_env.num_envs} must be divisible by k+1={num_objectives} "
                "(one block of simulations per VPPO copy)"
            )
        if train_env.autoreset_mode.value != "SameStep":
            raise ValueError("the training environment must use autoreset_mode=SAME_STEP")
        self.device = train_env.device
        self.train_env = train_env
        self.executor = executor
        self.actor_hidden = tuple(policy.hidden)
        self.obs_dim = train_env.single_observation_space.shape[0]
        self.action_dim = train_env.single_action_space.shape[0]
        self.num_objectives = num_objectives
        self.generator = generator
        self.jacobian_critic = VectorizedCritic(
            num_objectives, self.obs_dim, self.critic_hidden, seed
        ).to(self.device)
        self.walk_critic = VectorizedCritic(1, self.obs_dim, self.critic_hidden, seed + 1).to(
            self.device
        )
        self.jacobian_critic_opt = self._adam(self.jacobian_critic.parameters())
        self.walk_critic_opt = self._adam(self.walk_critic.parameters())
        self.jacobian_returns = RunningMeanStd(num_objectives, device=self.device)
        self.walk_returns = RunningMeanStd(1, device=self.device)

    def _adam(self, params) -> torch.optim.Adam:
        return torch.optim.Adam(params, lr=self.learning_rate, eps=self.adam_eps)

    def _actor(self, solutions: np.ndarray) -> VectorizedActor:
        actor = VectorizedActor(len(solutions), self.obs_dim, self.action_dim, self.actor_hidden)
        actor = actor.to(self.device)
        actor.set_solutions(solutions)
        if not self.adaptive_std:
            with torch.no_grad():
                actor.log_std.zero_()
            actor.log_std.requires_grad_(False)
        return actor

    # ------------------------------------------------------------- the phases
    def compute_jacobian(
        self, theta: np.ndarray, stats: RunningMeanStd, reward_fn: RewardFn, seed: int
    ) -> PhaseResult:
        """Estimate ∇f and ∇m_j at θ_μ as parameter deltas after N1 PPO iterations.

        Args:
            theta: (D,) search policy θ_μ.
            stats: its observation statistics (one policy; used frozen).
            reward_fn: per-step reward of the objective f, (T, N) from a rollout.
            seed: reset seed of the simulations.

        Returns:
            ``solutions`` holds the trained copies; the Jacobian is ``solutions - theta``.
        """
        k1 = self.num_objectives
        actor = self._actor(np.repeat(theta[None], k1, axis=0))
        copies_stats = RunningMeanStd.stack([stats.to(self.device)] * k1)
        actor_opt = self._adam([p for p in actor.parameters() if p.requires_grad])
        self.executor.start(seed)
        block = self.train_env.num_envs // k1
        rollouts, diagnostics = [], []
        for _ in range(self.jacobian_iterations):
            rollout, pdata = self.executor.collect(
                actor, copies_stats, self.rollout_length, self.generator, update_stats=False
            )
            # copy 0: the reward of f; copy j: the measure proxy δ_j after the step
            rewards = rollout.next_contacts.new_zeros(rollout.rewards.shape)
            f_rollout = rollout.columns(0, block)
            rewards[:, :block] = reward_fn(f_rollout)
            for j in range(1, k1):
                copy_j = slice(j * block, (j + 1) * block)
                rewards[:, copy_j] = rollout.next_contacts[:, copy_j, j - 1]
            diagnostics.append(
                ppo_update(
                    self.ppo, self.generator, actor, actor_opt, self.jacobian_critic,
                    self.jacobian_critic_opt, self.jacobian_returns, rollout, pdata, rewards,
                )
            )  # fmt: skip
            rollouts.append(f_rollout)
        steps = self.jacobian_iterations * self.rollout_length * self.train_env.num_envs
        return PhaseResult(actor.get_solutions(), copies_stats, rollouts, _mean(diagnostics), steps)

    def walk(
        self,
        theta: np.ndarray,
        stats: RunningMeanStd,
        coefficients: np.ndarray,
        reward_fn: RewardFn,
        seed: int,
    ) -> PhaseResult:
        """Move θ_μ by N2 PPO iterations on c_0·r̂ + Σ_j c_j·δ_j.

        Args:
            theta: (D,) search policy θ_μ.
            stats: its observation statistics (copied, then updated).
            coefficients: (k+1,) gradient coefficients c, the ES mean.
            reward_fn: per-step reward r̂, (T, N) from a rollout.
            seed: reset seed of the simulations.

        Returns:
            ``solutions[0]`` is the moved θ_μ and ``stats`` its statistics.
        """
        actor = self._actor(theta[None])
        stats = stats.to(self.device).select([0])
        actor_opt = self._adam([p for p in actor.parameters() if p.requires_grad])
        c = torch.as_tensor(coefficients, dtype=torch.float32, device=self.device)
        self.executor.start(seed)
        rollouts, diagnostics = [], []
        for _ in range(self.walk_iterations):
            rollout, pdata = self.executor.collect(
                actor, stats, self.rollout_length, self.generator, update_stats=True
            )
            rewards = walk_rewards(c, reward_fn(rollout), rollout.next_contacts)
            diagnostics.append(
                ppo_update(
                    self.ppo, self.generator, actor, actor_opt, self.walk_critic,
                    self.walk_critic_opt, self.walk_returns, rollout, pdata, rewards,
                )
            )  # fmt: skip
            rollouts.append(rollout)
        steps = self.walk_iterations * self.rollout_length * self.train_env.num_envs
        return PhaseResult(actor.get_solutions(), stats, rollouts, _mean(diagnostics), steps)

    # ------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict:
        """Critics, their optimisers and return statistics (the run keeps the noise)."""
        return {name: getattr(self, name).state_dict() for name in _PERSISTENT}

    def load_state_dict(self, state: dict) -> None:
        """Restore :meth:`state_dict` (after :meth:`setup`)."""
        for name in _PERSISTENT:
            getattr(self, name).load_state_dict(state[name])


def walk_rewards(
    coefficients: torch.Tensor, learned: torch.Tensor, next_contacts: torch.Tensor
) -> torch.Tensor:
    """The walk's per-step reward c_0·r̂ + Σ_j c_j·δ_j.

    Args:
        coefficients: (k+1,) gradient coefficients c, on the rewards' device and dtype.
        learned: (T, N) rewards r̂ of the objective.
        next_contacts: (T, N, k) contact flags δ(s_{t+1}) after each step.

    Returns:
        (T, N) rewards.
    """
    return coefficients[0] * learned + (next_contacts * coefficients[1:]).sum(-1)


def _mean(diagnostics: list[dict[str, float]]) -> dict[str, float]:
    return {key: float(np.mean([d[key] for d in diagnostics])) for key in diagnostics[0]}
