"""Reward forms: each named transform's formula, the models that share them, and the options
that change what a fall is worth (``absorbing: fixed``) and the critic's cadence."""

from __future__ import annotations

import math

import pytest
import torch

from qdil.rewards.builtin.airl import AIRL
from qdil.rewards.builtin.gail import GAIL
from qdil.rewards.builtin.maxent_irl import MaxEntIRL
from qdil.rewards.builtin.wae import MCWAEWGAIL, WAEGAIL
from qdil.rewards.contract import ACT, OBS, K, demos_of, synthetic, train
from qdil.rewards.forms import FORMS, ScoreStats, get_form
from qdil.upgrades import upgraded

STATS = ScoreStats(expert_mean=11.0, policy_mean=-1.0, policy_std=2.0, min_gap=1.0)


def test_each_form_is_its_formula() -> None:
    s = torch.tensor([-30.0, -1.0, 0.0, 5.0, 11.0, 40.0])
    sig = torch.sigmoid
    cal = 4.0 * (s - 5.0) / 12.0  # 2·2·(s − midpoint)/gap
    std = (s + 1.0) / 2.0
    expected = {
        "raw": s,
        "log1-d": -torch.log(1 - sig(s) + 1e-8),
        "logd": torch.log(sig(s) + 1e-8),
        "sigmoid": sig(s),
        "calibrated": -torch.log(1 - sig(cal) + 1e-8),
        "calibrated_sigmoid": sig(cal),
        "standardized": -torch.log(1 - sig(std) + 1e-8),
        "standardized_logit": std,
    }
    assert set(expected) == set(FORMS)
    for name, values in expected.items():
        torch.testing.assert_close(get_form(name)(s, STATS), values, msg=name)
    with pytest.raises(ValueError, match=r"unknown reward_form 'gail'.*calibrated_sigmoid"):
        get_form("gail")


def test_calibrated_sigmoid_is_bounded_positive_and_keeps_its_scale_as_the_critic_grows() -> None:
    form = get_form("calibrated_sigmoid")
    # the policy's mean pays σ(−2), the expert's σ(2), whatever the critic's range
    for scale in (1.0, 25.0, 1e4):
        stats = ScoreStats(2.0 * scale, -2.0 * scale, 0.5 * scale, 1.0)
        scores = scale * torch.tensor([-2.0, 2.0, -3.0, -1.0, -1e3])
        rewards = form(scores, stats)
        torch.testing.assert_close(rewards[:2], torch.sigmoid(torch.tensor([-2.0, 2.0])))
        # a policy transition one σ_π above or below its mean still differs from it
        torch.testing.assert_close(rewards[2:4], torch.sigmoid(torch.tensor([-3.0, -1.0])))
        assert bool((rewards >= 0).all() and (rewards < 1).all())
    assert form.lower_bound == 0.0 and form.needs_stats
    # the plain sigmoid of the same grown critic pays the policy's mean nothing
    assert float(get_form("sigmoid")(torch.tensor([-2e4]), STATS)) == 0.0
    assert get_form("raw").lower_bound == -math.inf and not get_form("raw").needs_stats


@pytest.mark.parametrize(
    ("model", "default"),
    [
        (GAIL, "log1-d"),
        (AIRL, "raw"),
        (MaxEntIRL, "raw"),
        (WAEGAIL, "log1-d"),
        (MCWAEWGAIL, "log1-d"),
    ],
)
def test_every_adversarial_model_hands_on_its_form_of_its_score(model, default) -> None:
    expert, policy = synthetic(2.0, 200, seed=1), synthetic(-2.0, 200, seed=2)
    assert model(OBS, ACT, K).form.name == default
    trained, metrics = train(
        model(OBS, ACT, K, reward_form="calibrated_sigmoid", batch_size=50), expert, policy, 3
    )
    last = metrics[-1]
    # the statistics the form reads were measured after the update and are logged
    assert trained.stats.expert_mean == pytest.approx(last["critic_expert"])
    assert trained.stats.policy_mean == pytest.approx(last["critic_policy"])
    with torch.no_grad():
        score = trained.score(policy)
        expected = get_form("calibrated_sigmoid")(score, trained.stats)
        torch.testing.assert_close(trained.reward(policy), expected)
    assert last["reward_policy"] == pytest.approx(float(expected.mean()), rel=1e-5)
    # the statistics travel with checkpoints
    clone = model(OBS, ACT, K, reward_form="calibrated_sigmoid", batch_size=50)
    clone.load_state_dict(trained.state_dict())
    torch.testing.assert_close(clone.reward(policy), trained.reward(policy))


def test_checkpoints_from_before_the_shared_statistics_still_load() -> None:
    model = GAIL(OBS, ACT, K)
    old = {
        key: value
        for key, value in model.state_dict().items()
        if key not in ("critic_means", "critic_policy_std")
    }
    clone = GAIL(OBS, ACT, K)
    clone.load_state_dict(old)
    assert clone.critic_means.tolist() == [2.0, -2.0] and float(clone.critic_policy_std) == 1.0


def test_steps_per_update_sets_the_critics_cadence() -> None:
    expert, policy = synthetic(2.0, 200, seed=3), synthetic(-2.0, 200, seed=4)
    model = GAIL(OBS, ACT, K, batch_size=50, steps_per_update=7)
    pairs = list(model.minibatches(expert, policy))
    assert len(pairs) == 7 and all(len(e) == len(p) == 50 for e, p in pairs)
    # one whole pass of 4 minibatches, then 3 of a fresh shuffle: every expert row in the first
    first = torch.cat([e.obs for e, _ in pairs[:4]])
    assert torch.equal(first.sort(0).values, expert.obs.sort(0).values)
    # as many steps as epochs would take are the same update, bit for bit
    torch.manual_seed(0)
    by_epochs, _ = train(GAIL(OBS, ACT, K, batch_size=50, epochs=2), expert, policy, 2)
    torch.manual_seed(0)
    by_steps, _ = train(GAIL(OBS, ACT, K, batch_size=50, steps_per_update=8), expert, policy, 2)
    for key, value in by_epochs.state_dict().items():
        assert torch.equal(value, by_steps.state_dict()[key]), key
    with pytest.raises(ValueError, match="steps_per_update must be positive"):
        GAIL(OBS, ACT, K, steps_per_update=0)


@pytest.mark.parametrize("cls", [GAIL, AIRL, MaxEntIRL, WAEGAIL, MCWAEWGAIL])
def test_feature_clip_bounds_the_standardised_inputs_of_every_adversarial_model(cls) -> None:
    """A feature the demonstrations hold constant standardises to thousands when it moves
    (a contact force on a fallen body); the clip holds it at the bound, as obs_clip does."""
    expert, policy = synthetic(0.0, 64, seed=1), synthetic(0.0, 64, seed=2)
    expert.obs[:, 0] = 0.5  # constant in the demonstrations: its std floors at 1e-3
    policy.obs[:5, 0] = 3.0  # ... and a policy leaves it
    plain, clipped = cls(OBS, ACT, K), cls(OBS, ACT, K, feature_clip=10.0)
    for model in (plain, clipped):
        model.setup(demos_of(expert))
    free, bounded = plain.features(policy), clipped.features(policy)
    assert float(free[:5, 0].min()) > 2000.0
    assert torch.equal(bounded[:5, 0], torch.full((5,), 10.0))
    inside = free.abs() <= 10.0  # everything within the bound is untouched
    assert torch.equal(bounded[inside], free[inside])
    assert float(bounded[:, : OBS + ACT].abs().max()) <= 10.0
    with pytest.raises(ValueError, match="feature_clip must be > 0 or null, got 0"):
        cls(OBS, ACT, K, feature_clip=0)


def test_older_recipes_name_their_forms_as_today() -> None:
    def form_of(class_path: str, reward_type: str) -> dict:
        old = {"reward": {"class_path": class_path, "init_args": {"reward_type": reward_type}}}
        return upgraded(old)["reward"]["init_args"]

    assert form_of("mcwae_wgail", "gail") == {"reward_form": "log1-d"}
    assert form_of("mcwae_wgail", "critic") == {"reward_form": "raw"}
    assert form_of("mcwae_wgail", "standardized") == {"reward_form": "standardized"}
    assert form_of("gail", "logit") == {"reward_form": "raw"}
    assert form_of("airl", "f") == {"reward_form": "raw"}
    assert form_of("qdil.rewards.builtin.airl.AIRL", "logit") == {
        "reward_form": "raw",
        "score_type": "logit",
    }
