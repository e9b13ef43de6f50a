"""Contract tests run over every registered reward model: built-ins and plugins.

The checks live in the package (:mod:`qdil.rewards.contract`), so that a plugin author runs
the same ones without a source checkout (``python -m qdil.rewards.contract NAME``).
"""

from __future__ import annotations

import pytest

from qdil.rewards import list_rewards
from qdil.rewards.contract import CHECKS, main

NAMES = [entry.name for entry in list_rewards()]


@pytest.mark.parametrize("check", list(CHECKS.values()), ids=list(CHECKS))
@pytest.mark.parametrize("name", NAMES)
def test_contract(name: str, check) -> None:
    note = check(name)
    if note:
        pytest.skip(note)


def test_the_command_reports_each_check_and_fails_on_a_failure(monkeypatch, capsys) -> None:
    """``python -m qdil.rewards.contract``: one line per check, exit 1 when one fails."""
    assert main(["true_reward"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == len(CHECKS) and lines[0].startswith("PASS true_reward rewards_have")
    assert "SKIP true_reward training_reaches_every_parameter: true_reward has no" in lines[1]

    def broken(name: str) -> None:
        raise AssertionError(f"{name}: broken on purpose")

    monkeypatch.setitem(CHECKS, "state_survives_a_checkpoint_round_trip", broken)
    assert main(["true_reward"]) == 1
    out = capsys.readouterr().out
    assert "FAIL true_reward state_survives_a_checkpoint_round_trip: true_reward: broken" in out


def test_an_unknown_name_is_a_usage_error(capsys) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["nosuch"])
    assert exit_.value.code == 2
    assert "unknown reward model 'nosuch'" in capsys.readouterr().err
