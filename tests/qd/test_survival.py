"""The survival figures: which steps come before a fall, and the tally of rewards there."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import torch

from qdil.data import Rollout
from qdil.qd.survival import SurvivalTally, before_termination

# three simulations over 6 steps: 0 falls at step 4; 1 is truncated at step 2 and its next
# episode runs past the rollout; 2 falls at steps 1 and 5
DONES = torch.tensor(
    [[0, 0, 0], [0, 0, 1], [0, 1, 0], [0, 0, 0], [1, 0, 0], [0, 0, 1]], dtype=torch.float32
)
TERMINATED = DONES * torch.tensor([1.0, 0.0, 1.0])


def test_the_steps_within_the_window_of_a_termination() -> None:
    near = before_termination(DONES, TERMINATED, window=2)
    expected = torch.zeros(6, 3, dtype=torch.bool)
    expected[3:5, 0] = True  # the fall at 4 and the step before
    expected[0:2, 2] = True
    expected[4:6, 2] = True
    assert torch.equal(near, expected)
    assert not before_termination(DONES, TERMINATED, window=0).any()
    # a window longer than the episodes: every step of a falling episode, none of the others
    everything = before_termination(DONES, TERMINATED, window=10)
    assert everything[:, 2].all() and everything[:5, 0].all() and not everything[5, 0]
    assert not everything[:, 1].any()


def _rollout() -> Rollout:
    """The simulations above; the first one's last step is evaluation padding."""
    valid = torch.ones(6, 3)
    valid[5, 0] = 0.0  # padding after an evaluation episode: counted nowhere
    zeros = torch.zeros(6, 3)
    return Rollout(
        obs=torch.zeros(6, 3, 1),
        actions=torch.zeros(6, 3, 1),
        contacts=torch.zeros(6, 3, 2),
        next_obs=torch.zeros(6, 3, 1),
        next_contacts=torch.zeros(6, 3, 2),
        rewards=zeros,
        dones=DONES,
        terminated=TERMINATED,
        log_probs=zeros,
        valid=valid,
        starts=zeros,
    )


def test_the_tally_averages_rewards_before_falls_and_elsewhere() -> None:
    rewards = torch.arange(18, dtype=torch.float32).reshape(6, 3)
    rollout = _rollout()
    valid = rollout.valid
    tally = SurvivalTally(window=2)
    tally.add(rollout, rewards)
    tally.add(rollout, rewards)  # a second rollout of the iteration adds to the sums
    near = before_termination(DONES, TERMINATED, 2)
    far = (valid > 0) & ~near
    metrics = tally.metrics()
    assert metrics["survival/reward_before_fall"] == float(rewards[near].double().mean())
    assert metrics["survival/reward_alive"] == float(rewards[far].double().mean())
    assert metrics["survival/falls_per_1k_steps"] == 1000.0 * 3 / 17


def test_a_tally_of_nothing_says_nan() -> None:
    assert all(math.isnan(v) for v in SurvivalTally().metrics().values())


def test_every_run_logs_the_survival_figures(smoke_run: Path) -> None:
    with open(smoke_run / "metrics.csv", newline="") as file:
        (row,) = csv.DictReader(file)
    for prefix in ("", "walk_"):  # the learned reward, and what the walk optimises
        assert math.isfinite(float(row[f"survival/{prefix}reward_alive"]))
        assert float(row[f"survival/{prefix}falls_per_1k_steps"]) >= 0.0


def test_the_walk_figures_weigh_the_reward_and_the_contacts_by_the_coefficients() -> None:
    from qdil.qd.iteration_reward import walk_survival

    rollout = _rollout()
    rollout.next_contacts[..., 0] = 1.0  # the first foot down throughout
    learned = torch.arange(18, dtype=torch.float32).reshape(6, 3)
    figures = walk_survival([rollout, rollout], [learned, learned], np.array([2.0, -1.0, 5.0]))
    tally = SurvivalTally(prefix="walk_")
    tally.add(rollout, 2.0 * learned - 1.0)
    assert figures == tally.metrics()
    assert walk_survival([], [], np.ones(3)) == {}
