"""The EBC bonus (bonus.type: ebc) against its equation on hand-built archives and rollouts."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch
from ribs.archives import GridArchive

from qdil.config import BonusConfig
from qdil.data import Rollout
from qdil.rewards.bonus import ExplorationBonus
from qdil.rewards.builtin import GAIL
from qdil.rewards.ebc import EBCBonus
from qdil.run import with_bonus


class _Constant(GAIL):
    """A model whose rewards are 1.0 everywhere, so that what the bonus adds is plain."""

    def __init__(self) -> None:
        super().__init__(1, 1, 2)

    def predict_reward(self, rollout: Rollout, *, update: bool = False) -> torch.Tensor:
        return torch.ones(rollout.rewards.shape)

    def update(self, expert: object, policy: object, iteration: int) -> dict[str, float]:
        return {}


def grid(occupied: list[list[float]], cells: int = 4) -> GridArchive:
    """A cells×cells archive over [0, 1]^2 with an elite at each of ``occupied``."""
    archive = GridArchive(solution_dim=1, dims=[cells, cells], ranges=[(0.0, 1.0)] * 2)
    if occupied:
        n = len(occupied)
        archive.add(np.zeros((n, 1)), np.zeros(n), np.array(occupied))
    return archive


def rollout_of(contacts: torch.Tensor, valid: torch.Tensor | None = None) -> Rollout:
    """A rollout (T, N) of the given δ(s_t) (T, N, 2); everything else zero."""
    steps, n, _ = contacts.shape
    zeros = torch.zeros(steps, n)
    obs = torch.zeros(steps, n, 1)
    valid = torch.ones(steps, n) if valid is None else valid
    return Rollout(
        obs, obs, contacts, obs, contacts, zeros, zeros, zeros, zeros, valid, zeros.clone()
    )


# three simulations over four steps: their window means are (0, 0), (0.5, 1) and (1, 0.25)
CONTACTS = torch.tensor(
    [
        [[0.0, 0.0], [0.0, 1.0], [1.0, 0.0]],
        [[0.0, 0.0], [1.0, 1.0], [1.0, 1.0]],
        [[0.0, 0.0], [0.0, 1.0], [1.0, 0.0]],
        [[0.0, 0.0], [1.0, 1.0], [1.0, 0.0]],
    ]
)


def test_the_window_measure_is_the_mean_over_valid_steps_across_episode_ends() -> None:
    np.testing.assert_allclose(
        EBCBonus.window_measures(rollout_of(CONTACTS)).numpy(), [[0, 0], [0.5, 1], [1, 0.25]]
    )
    valid = torch.ones(4, 3)
    valid[2:, 2] = 0  # column 2 padded after two steps: its mean is over those two
    measures = EBCBonus.window_measures(rollout_of(CONTACTS, valid))
    np.testing.assert_allclose(measures[2].numpy(), [1.0, 0.5])


def test_the_bonus_is_offset_plus_weight_in_unoccupied_cells_at_every_step() -> None:
    # 4×4 grid: (0, 0) -> cell (0, 0) occupied; (0.5, 1) -> (2, 3) empty; (1, 0.25) -> (3, 1)
    archive = grid([[0.1, 0.1], [0.9, 0.3]])
    bonus = EBCBonus(_Constant(), lambda: archive, weight=2.0, offset=0.25)
    rewards = bonus.predict_reward(rollout_of(CONTACTS), update=True)
    expected = torch.tensor([1.25, 3.25, 1.25]).expand(4, -1)
    torch.testing.assert_close(rewards, expected, rtol=0, atol=0)
    assert rewards.dtype == torch.float32


def test_evaluations_get_no_bonus_and_leave_the_archive_objective_alone() -> None:
    bonus = EBCBonus(_Constant(), lambda: grid([]), weight=2.0, offset=0.25)
    rewards = bonus.predict_reward(rollout_of(CONTACTS))  # update=False: an evaluation
    torch.testing.assert_close(rewards, torch.ones(4, 3), rtol=0, atol=0)
    assert bonus.update(None, None, 1)["bonus_per_step"] == 0.0  # nothing was counted


def test_an_empty_archive_pays_every_window() -> None:
    bonus = EBCBonus(_Constant(), lambda: grid([]), weight=2.0)
    rewards = bonus.predict_reward(rollout_of(CONTACTS), update=True)
    torch.testing.assert_close(rewards, torch.full((4, 3), 3.0), rtol=0, atol=0)


def test_update_reports_the_balance_and_the_share_of_novel_windows_then_resets() -> None:
    archive = grid([[0.1, 0.1]])
    bonus = EBCBonus(_Constant(), lambda: archive, weight=2.0)
    valid = torch.ones(4, 3)
    valid[3, 0] = 0  # one padded step: 11 valid steps, 8 of them in novel windows
    bonus.predict_reward(rollout_of(CONTACTS, valid), update=True)
    metrics = bonus.update(None, None, 1)
    assert metrics["learned_per_step"] == pytest.approx(1.0)
    assert metrics["bonus_per_step"] == pytest.approx(2.0 * 8 / 11)
    assert metrics["bonus_novel_share"] == pytest.approx(2 / 3)
    again = bonus.update(None, None, 2)  # no rollout since: no share, no bonus
    assert "bonus_novel_share" not in again and again["bonus_per_step"] == 0.0


def test_the_bonus_reads_the_archive_the_run_holds_now() -> None:
    """A resume replaces ``archives.main`` with the checkpoint's; the bonus must follow it."""
    archives = SimpleNamespace(main=grid([]))
    config = BonusConfig(enabled=True, type="ebc", weight=2.0)
    bonus = with_bonus(_Constant(), config, archives)
    assert isinstance(bonus, EBCBonus) and bonus.name == "gail+ebc"
    rollout = rollout_of(CONTACTS)
    assert bonus.predict_reward(rollout, update=True)[0].tolist() == [3.0, 3.0, 3.0]
    archives.main = grid([[0.0, 0.0], [0.5, 1.0], [1.0, 0.25]])
    assert bonus.predict_reward(rollout, update=True)[0].tolist() == [1.0, 1.0, 1.0]


def test_the_default_bonus_section_is_the_single_step_bonus() -> None:
    archives = SimpleNamespace(main=grid([]))
    assert with_bonus(_Constant(), BonusConfig(), archives).name == "gail"  # disabled
    bonus = with_bonus(_Constant(), BonusConfig(enabled=True, cells=3), archives)
    assert type(bonus) is ExplorationBonus and bonus.cells == 3 and bonus.counts.shape == (9,)


@pytest.mark.parametrize(
    ("config", "words"),
    [
        (BonusConfig(type="ebc", cells=4), "bonus.cells applies to bonus.type single_step only"),
        (BonusConfig(offset=0.5), "bonus.offset applies to bonus.type ebc only"),
        (
            BonusConfig(type="ebc", in_fitness=False),
            "bonus.in_fitness applies to bonus.type single_step only",
        ),
    ],
)
def test_settings_of_the_other_bonus_type_are_refused_by_name(
    config: BonusConfig, words: str
) -> None:
    with pytest.raises(ValueError, match=words):
        with_bonus(_Constant(), config, SimpleNamespace(main=grid([])))
