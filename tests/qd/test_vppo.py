from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from qdil.config import PolicyConfig
from qdil.envs.faces import torch_face
from qdil.envs.vector import LocomotionVectorEnv
from qdil.executors.local import LocalExecutor
from qdil.qd.scoring import Scorer
from qdil.qd.vppo import VPPO
from qdil.rl.collect import Collector
from qdil.rl.networks import VectorizedActor
from qdil.rl.normalize import RunningMeanStd
from qdil.rl.ppo import ppo_update
from qdil.run import set_up_policies
from tests.vppo_setup import make_vppo


@pytest.fixture(scope="module")
def vppo_scorer() -> tuple[VPPO, Scorer]:
    return make_vppo(num_envs=6, eval_envs=4, max_episode_steps=40, target_kl=None)


@pytest.fixture(scope="module")
def vppo(vppo_scorer) -> VPPO:
    return vppo_scorer[0]


def initial(seed: int) -> np.ndarray:
    return VectorizedActor.initial_solution(17, 6, (128, 128), seed)


SOLUTION_DIM = VectorizedActor.solution_dim(17, 6, (128, 128))


def test_jacobian_has_one_row_per_objective_and_leaves_sigma_alone(vppo) -> None:
    theta = initial(0)
    phase = vppo.compute_jacobian(theta, RunningMeanStd(1, (17,)), lambda r: r.rewards, seed=1)
    assert phase.solutions.shape == (3, SOLUTION_DIM)
    jacobian = phase.solutions - theta
    assert np.all(np.linalg.norm(jacobian, axis=1) > 0)
    np.testing.assert_array_equal(jacobian[:, -6:], 0.0)  # log σ is fixed (adaptive_std=False)
    assert len(phase.rollouts) == 2 and phase.rollouts[0].obs.shape == (16, 2, 17)
    assert phase.env_steps == 2 * 16 * 6
    assert set(phase.diagnostics) >= {
        "policy_loss",
        "value_loss",
        "approx_kl",
        "explained_variance",
    }


def test_walk_moves_theta_and_updates_its_statistics(vppo) -> None:
    theta = initial(0)
    stats = RunningMeanStd(1, (17,))
    phase = vppo.walk(theta, stats, np.array([1.0, 0.5, -0.5]), lambda r: r.rewards, seed=2)
    assert phase.solutions.shape == (1, SOLUTION_DIM)
    assert not np.allclose(phase.solutions[0], theta)
    assert phase.stats.count[0] > 2 * 16 * 6 - 1 and stats.count[0] < 1  # input untouched


def test_evaluation_of_recorded_true_rewards_equals_the_true_return(vppo_scorer) -> None:
    scorer = vppo_scorer[1]
    theta = np.stack([initial(s) for s in (0, 1)])
    stats = RunningMeanStd(2, (17,))
    recorded = scorer.evaluate(theta, stats, 2, seed=3, reward_fn=lambda r: r.rewards)
    plain = scorer.evaluate(theta, stats, 2, seed=3, deterministic=True)
    assert recorded.objective.shape == (2,) and recorded.measures.shape == (2, 2)
    np.testing.assert_allclose(recorded.objective, recorded.true_objective, rtol=1e-5)
    np.testing.assert_array_equal(plain.objective, plain.true_objective)
    assert np.all((recorded.measures >= 0) & (recorded.measures <= 1))
    assert np.all((plain.lengths >= 1) & (plain.lengths <= 40))
    again = scorer.evaluate(theta, stats, 2, seed=3, deterministic=True)
    np.testing.assert_array_equal(again.true_objective, plain.true_objective)


def test_collector_aligns_contacts_with_observations() -> None:
    env = LocomotionVectorEnv("Hopper-v5", 4, max_episode_steps=30, autoreset_mode="SameStep")
    collector = Collector(torch_face(env))
    collector.start(seed=0)
    actor = VectorizedActor(2, 11, 3)
    actor.set_solutions(np.stack([VectorizedActor.initial_solution(11, 3, seed=s) for s in (0, 1)]))
    rollout, pdata = collector.collect(actor, RunningMeanStd(2, (11,)), 60, torch.Generator(), True)
    done = rollout.dones.bool()
    assert done.any()
    # δ(s_{t+1}) after step t is δ of the next observation wherever the episode goes on
    same = ~done[:-1]
    torch.testing.assert_close(rollout.contacts[1:][same], rollout.next_contacts[:-1][same])
    torch.testing.assert_close(rollout.obs[1:][same], rollout.next_obs[:-1][same])
    # at an episode end the next observation is the final one, not the reset one
    assert not torch.allclose(rollout.obs[1:][~same], rollout.next_obs[:-1][~same])
    assert pdata.actions.shape == (60, 4, 3) and torch.all(rollout.actions.abs() <= 1)
    returns, lengths = collector.pop_episode_stats()
    assert len(returns) == int(done.sum()) and all(1 <= n <= 30 for n in lengths)


def test_ppo_update_moves_the_policy_towards_higher_advantage() -> None:
    """One-step episodes rewarding the first action dimension: its mean must rise."""
    algo = VPPO(
        rollout_length=64,
        num_minibatches=4,
        update_epochs=4,
        target_kl=None,
        learning_rate=3e-3,
        adaptive_std=True,
    )
    env = LocomotionVectorEnv("HalfCheetah-v5", 6, autoreset_mode="SameStep")
    set_up_policies(env, LocomotionVectorEnv("HalfCheetah-v5", 1, autoreset_mode="Disabled"), algo)
    actor = VectorizedActor(1, 17, 6)
    actor.set_solutions(VectorizedActor.initial_solution(17, 6, seed=0)[None])
    stats = RunningMeanStd(1, (17,))
    algo.executor.start(seed=0)
    optimizer = algo._adam(actor.parameters())
    obs = torch.zeros(1, 1, 17)
    with torch.no_grad():
        before = float(actor(obs)[0, 0, 0])
    for _ in range(3):
        rollout, pdata = algo.executor.collect(actor, stats, 64, algo.generator, False)
        rewards = pdata.actions[..., 0]
        ones = torch.ones_like(rewards)
        rollout = dataclasses.replace(rollout, dones=ones, terminated=ones)
        ppo_update(
            algo.ppo, algo.generator, actor, optimizer, algo.walk_critic, algo.walk_critic_opt,
            algo.walk_returns, rollout, pdata, rewards,
        )  # fmt: skip
    with torch.no_grad():
        assert float(actor(obs)[0, 0, 0]) > before + 0.05


def test_num_envs_must_split_among_copies() -> None:
    algo = VPPO()
    env = LocomotionVectorEnv("Walker2d-v5", 4, autoreset_mode="SameStep")
    with pytest.raises(ValueError, match="divisible by k\\+1=3"):
        algo.setup(env, LocalExecutor(), PolicyConfig(), torch.Generator(), seed=0)


@pytest.mark.parametrize("update_stats", [False, True])
def test_next_state_values_equal_a_second_critic_pass_bit_for_bit(update_stats: bool) -> None:
    """GAE's V(s_{t+1}) reuses V(s_t) while episodes go on, with the very bits of a pass of
    the critic over every next observation (the Jacobian copies' frozen statistics and the
    walk's updated ones)."""
    from qdil.rl.networks import VectorizedCritic
    from qdil.rl.ppo import next_state_values, to_policies

    env = LocomotionVectorEnv("Hopper-v5", 6, max_episode_steps=30, autoreset_mode="SameStep")
    collector = Collector(torch_face(env))
    collector.start(seed=3)
    actor = VectorizedActor(3, 11, 3)
    actor.set_solutions(
        np.stack([VectorizedActor.initial_solution(11, 3, seed=s) for s in range(3)])
    )
    stats = RunningMeanStd(3, (11,))
    generator = torch.Generator().manual_seed(0)
    for _ in range(2):  # the second rollout normalises with statistics that moved
        rollout, pdata = collector.collect(actor, stats, 40, generator, update_stats)
    assert rollout.dones.sum() >= 6
    critic = VectorizedCritic(3, 11)
    obs, next_obs = to_policies(pdata.norm_obs, 3), to_policies(pdata.norm_next_obs, 3)
    with torch.no_grad():
        reused = next_state_values(critic, critic(obs), next_obs, rollout.dones, 40)
        assert torch.equal(reused, critic(next_obs))
