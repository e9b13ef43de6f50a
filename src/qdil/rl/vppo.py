"""VPPO: PPGA's vectorised PPO, the gradient estimator and the walk of the search policy.

Reads top to bottom (CleanRL style): :meth:`VPPO.compute_jacobian` trains k+1 copies of
θ_μ side by side, :meth:`VPPO.walk` moves θ_μ, both with the same PPO update
(:func:`qdil.rl.ppo.ppo_update`); an executor steps the simulations. Why each detail is as
it is: ``docs/concepts/vppo.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np
import torch

from qdil.data import Rollout
from qdil.envs.vector import LocomotionVectorEnv
from qdil.executors.base import Executor
from qdil.executors.local import LocalExecutor
from qdil.rl.collect import ActionMap, PolicyData, RewardFn
from qdil.rl.episodes import Evaluation, EvaluationGroup
from qdil.rl.networks import VectorizedActor, VectorizedCritic
from qdil.rl.normalize import RunningMeanStd
from qdil.rl.ppo import PPOSettings, ppo_update

# each phase's critic, its optimiser and return statistics: they persist across QD
# iterations and restarts (checkpointed beside the noise generator)
_PERSISTENT = tuple(
    f"{p}_{x}" for p in ("jacobian", "walk") for x in ("critic", "critic_opt", "returns")
)


@dataclass(frozen=True)
class PhaseResult:
    """What a VPPO phase hands back to the QD loop.

    Attributes:
        solutions: (P, D) trained solutions (P = k+1 for the Jacobian, 1 for the walk).
        stats: their observation statistics.
        rollouts: the rollouts of the reward-trained policy (copy 0, or the walking θ_μ).
        diagnostics: mean PPO diagnostics over the phase (``rl/...`` metrics).
        env_steps: simulated env steps.
    """

    solutions: np.ndarray
    stats: RunningMeanStd
    rollouts: list[Rollout]
    diagnostics: dict[str, float]
    env_steps: int


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
        obs_clip: bound of normalised observations.
        adaptive_std: learn the log standard deviations (PPGA: False for Walker2d and
            Humanoid, True for HalfCheetah).
        bootstrap_truncation: bootstrap time-limit truncations from the final state.
        actor_hidden: actor widths (paper: 128, 128).
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
        obs_clip: float = 10.0,
        adaptive_std: bool = False,
        bootstrap_truncation: bool = True,
        actor_hidden: Sequence[int] = (128, 128),
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
        self.obs_clip = obs_clip
        self.adaptive_std = adaptive_std
        self.bootstrap_truncation = bootstrap_truncation
        self.actor_hidden = tuple(actor_hidden)
        self.critic_hidden = tuple(critic_hidden)

    # ------------------------------------------------------------------ setup
    def setup(
        self,
        train_env: LocomotionVectorEnv,
        eval_env: LocomotionVectorEnv,
        seed: int,
        executor: Executor | None = None,
    ) -> None:
        """Bind the environments and build the persistent critics.

        The policies, critics, statistics, rollouts and the noise generator live on the
        physics' device, ``train_env.device``.

        Args:
            train_env: ``SAME_STEP`` environment of the PPO phases; its N must be divisible
                by k+1.
            eval_env: ``DISABLED`` environment of the evaluations, on the same device.
            seed: seed of the critics' initialisation and the action noise.
            executor: who steps the simulations (default: here, :class:`LocalExecutor`).

        Raises:
            ValueError: if N is not divisible by k+1, or the environments' devices differ
                (naming ``env.device``).
        """
        num_objectives = train_env.num_feet + 1
        if train_env.num_envs % num_objectives:
            raise ValueError(
                f"env.num_envs={train_env.num_envs} must be divisible by k+1={num_objectives} "
                "(one block of simulations per VPPO copy)"
            )
        if eval_env.device != train_env.device:
            raise ValueError(
                f"env.device: the training physics steps on {train_env.device} but the "
                f"evaluations' on {eval_env.device}; one env.device places both"
            )
        self.device = train_env.device
        self.train_env, self.eval_env = train_env, eval_env
        if train_env.autoreset_mode.value != "SameStep":
            raise ValueError("the training environment must use autoreset_mode=SAME_STEP")
        self.executor = LocalExecutor() if executor is None else executor
        self.executor.setup(train_env, eval_env, self.obs_clip)
        self.action_map = ActionMap(
            train_env.single_action_space.low, train_env.single_action_space.high, self.device
        )
        self.obs_dim = train_env.single_observation_space.shape[0]
        self.action_dim = train_env.single_action_space.shape[0]
        self.num_objectives = num_objectives
        self.generator = torch.Generator(device=self.device).manual_seed(seed)
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

    @property
    def solution_dim(self) -> int:
        """D, the length of a policy's flat parameter vector."""
        return VectorizedActor.solution_dim(self.obs_dim, self.action_dim, self.actor_hidden)

    def initial_solution(self, seed: int) -> np.ndarray:
        """(D,) PPGA's initial policy θ_0."""
        return VectorizedActor.initial_solution(
            self.obs_dim, self.action_dim, self.actor_hidden, seed
        )

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
                self._ppo_update("jacobian", actor, actor_opt, rollout, pdata, rewards)
            )
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
            rewards = c[0] * reward_fn(rollout) + (rollout.next_contacts * c[1:]).sum(-1)
            diagnostics.append(self._ppo_update("walk", actor, actor_opt, rollout, pdata, rewards))
            rollouts.append(rollout)
        steps = self.walk_iterations * self.rollout_length * self.train_env.num_envs
        return PhaseResult(actor.get_solutions(), stats, rollouts, _mean(diagnostics), steps)

    def evaluate(
        self,
        solutions: np.ndarray,
        stats: RunningMeanStd,
        episodes: int,
        seed: int,
        reward_fn: RewardFn | None = None,
        deterministic: bool = False,
    ) -> Evaluation:
        """Score P solutions over ``episodes`` episodes each (see ``evaluate_policies``)."""
        return self.evaluate_all([(solutions, stats, episodes, seed)], reward_fn, deterministic)[0]

    def evaluate_all(
        self,
        requests: list[tuple[np.ndarray, RunningMeanStd, int, int]],
        reward_fn: RewardFn | None = None,
        deterministic: bool = False,
    ) -> list[Evaluation]:
        """Score several groups of solutions, each over its own episodes and reset seed.

        On a device the executor plays the groups side by side, each with noise from a
        generator seeded with its reset seed; on the C engine in turns, with noise from the
        training generator (``docs/concepts/vppo.md``).

        Args:
            requests: ``(solutions (P, D), stats, episodes, seed)`` of each group.
            reward_fn: scores the episodes for the objective; ``None``: the true return.
            deterministic: act with the mean action or sample.

        Returns:
            One evaluation per group, in order.
        """
        groups = []
        for solutions, stats, episodes, seed in requests:
            actor = VectorizedActor(
                len(solutions), self.obs_dim, self.action_dim, self.actor_hidden
            ).to(self.device)
            actor.set_solutions(solutions)  # exactly the stored policies, log σ included
            generator = torch.Generator(device=self.device).manual_seed(seed)
            groups.append(EvaluationGroup(actor, stats.to(self.device), episodes, seed, generator))
        return self.executor.evaluate_all(groups, reward_fn, deterministic, self.generator)

    def log_probs(
        self, solution: np.ndarray, stats: RunningMeanStd, obs: torch.Tensor, actions: torch.Tensor
    ) -> torch.Tensor:
        """(B,) log π(a | s) of executed actions under one policy (for AIRL's discriminator).

        Args:
            solution: (D,) the policy.
            stats: its observation statistics (one policy).
            obs: (B, obs_dim) raw observations.
            actions: (B, action_dim) executed actions, mapped back to the policy's [-1, 1].
        """
        actor = VectorizedActor(1, self.obs_dim, self.action_dim, self.actor_hidden)
        actor = actor.to(self.device)
        actor.set_solutions(solution[None])
        action_map = self.action_map
        obs, actions, stats = obs.to(self.device), actions.to(self.device), stats.to(self.device)
        policy_actions = (actions - action_map.low) / action_map.half - 1.0
        with torch.no_grad():
            norm = stats.normalize(obs[None].double(), clip=self.obs_clip).float()
            return actor.distribution(norm).log_prob(policy_actions[None]).sum(-1)[0]

    # ---------------------------------------------------------------- PPO core
    def _ppo_update(
        self,
        phase: str,
        actor: VectorizedActor,
        actor_opt: torch.optim.Optimizer,
        rollout: Rollout,
        pdata: PolicyData,
        rewards: torch.Tensor,
    ) -> dict[str, float]:
        """One PPO iteration (:func:`qdil.rl.ppo.ppo_update`) on (T, N) ``rewards``.

        It trains the critic, critic optimiser and return statistics of ``phase``.
        """
        settings = PPOSettings(**{f.name: getattr(self, f.name) for f in fields(PPOSettings)})
        critic, critic_opt, return_stats = (
            getattr(self, f"{phase}_{x}") for x in ("critic", "critic_opt", "returns")
        )
        return ppo_update(
            settings, self.generator, actor, actor_opt, critic, critic_opt, return_stats,
            rollout, pdata, rewards,
        )  # fmt: skip

    # ------------------------------------------------------------ checkpoints
    def state_dict(self) -> dict:
        """Critics, their optimisers, return statistics and the noise generator."""
        state = {name: getattr(self, name).state_dict() for name in _PERSISTENT}
        return {**state, "generator": self.generator.get_state()}

    def load_state_dict(self, state: dict) -> None:
        """Restore :meth:`state_dict` (after :meth:`setup`)."""
        for name in _PERSISTENT:
            getattr(self, name).load_state_dict(state[name])
        self.generator.set_state(state["generator"])


def _mean(diagnostics: list[dict[str, float]]) -> dict[str, float]:
    return {key: float(np.mean([d[key] for d in diagnostics])) for key in diagnostics[0]}
