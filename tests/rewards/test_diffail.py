"""DiffAIL (plugins/qdil-diffail) against its equations on hand-built inputs.

The plugin is a separate package that the README's test command installs; without it these
tests are skipped, as the ``vail`` plugin's are.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F

pytest.importorskip("qdil_diffail", reason="plugins/qdil-diffail is not installed")

from qdil_diffail import DiffAIL
from qdil_diffail.diffusion import (
    Mish,
    NoisePredictor,
    linear_schedule,
    sinusoidal_embedding,
    squared_errors,
)
from qdil_diffail.model import discriminator_loss

from qdil.data import TransitionBatch
from qdil.rewards import get_reward, list_rewards
from qdil.rewards.contract import ACT, OBS, K, synthetic, train


def batch_of(obs: torch.Tensor, actions: torch.Tensor) -> TransitionBatch:
    n = obs.shape[0]
    contacts = torch.zeros(n, 2)
    return TransitionBatch(obs, actions, contacts, obs, contacts, torch.zeros(n), torch.zeros(n))


def silenced(model: DiffAIL) -> DiffAIL:
    """``model`` with a noise predictor that outputs 0 everywhere (zero last layer)."""
    last = model.denoiser.net[-1]
    torch.nn.init.zeros_(last.weight)
    torch.nn.init.zeros_(last.bias)
    return model


def test_it_registers_as_diffail_from_its_entry_point() -> None:
    assert get_reward("diffail") is DiffAIL and DiffAIL.name == "diffail"
    entry = {e.name: e for e in list_rewards()}["diffail"]
    assert entry.source == "entry point diffail (qdil-diffail)"
    assert DiffAIL.learned and DiffAIL.needs_demos and DiffAIL.prefers_expert


def test_linear_schedule_is_the_cumulative_product_of_one_minus_beta() -> None:
    np.testing.assert_allclose(linear_schedule(3, 0.1, 0.3).numpy(), [0.9, 0.72, 0.504], rtol=1e-6)


def test_timestep_embedding_is_sines_then_cosines_of_geometric_frequencies() -> None:
    code = sinusoidal_embedding(torch.tensor([0, 2]), 4)  # frequencies 1 and 1e-4
    np.testing.assert_allclose(code[0].numpy(), [0, 0, 1, 1], atol=1e-7)
    expected = [math.sin(2), math.sin(2e-4), math.cos(2), math.cos(2e-4)]
    np.testing.assert_allclose(code[1].numpy(), expected, rtol=1e-6)


def test_squared_error_noises_x0_with_the_schedule() -> None:
    # one linear layer set to return the x_t part of its input: e = (x_t − ε)²
    predictor = NoisePredictor(2, hidden=(), time_dim=4)
    with torch.no_grad():
        predictor.net[0].weight.zero_()
        predictor.net[0].weight[:, :2] = torch.eye(2)
        predictor.net[0].bias.zero_()
    alpha_bar = torch.tensor([0.64, 0.25])
    x0, noise = torch.tensor([[1.0, -2.0]]), torch.tensor([[0.5, 1.0]])
    errors = squared_errors(predictor, alpha_bar, x0, torch.tensor([1]), noise)
    x_t = 0.5 * x0 + math.sqrt(0.75) * noise  # √ᾱ = 0.5, √(1 − ᾱ) = √0.75
    torch.testing.assert_close(errors, (x_t - noise).square())


def test_reward_timesteps_are_the_midpoints_of_equal_slices() -> None:
    assert DiffAIL(3, 2, 2).reward_t.tolist() == list(range(100))
    assert DiffAIL(3, 2, 2, reward_timesteps=10).reward_t.tolist() == list(range(5, 100, 10))
    assert DiffAIL(3, 2, 2, reward_timesteps=1).reward_t.tolist() == [50]


@pytest.mark.parametrize(
    ("estimate", "d"),
    [
        # e = ε² on the fixed draws (0, 1, 0, 0, 0) and (2, 0, 0, 0, 0) of x = (s, a) in R^5:
        # the mean of e^{−e} over the 10 elements, or e^{−mean e}
        ("elementwise", (8 + math.exp(-1) + math.exp(-4)) / 10),
        ("loss", math.exp(-(1 + 4) / 10)),
    ],
)
def test_reward_is_minus_log_one_minus_d(estimate: str, d: float) -> None:
    model = silenced(DiffAIL(3, 2, 2, reward_timesteps=2, reward_estimate=estimate))
    model.reward_noise.copy_(torch.tensor([[0.0, 1.0, 0.0, 0.0, 0.0], [2.0, 0.0, 0.0, 0.0, 0.0]]))
    batch = batch_of(torch.randn(4, 3), torch.randn(4, 2))
    expected = torch.full((4,), -math.log(1 - d + 1e-8))
    torch.testing.assert_close(model.reward(batch), expected)


def test_reward_is_a_function_of_the_transition_alone() -> None:
    """Common random numbers: a transition's reward is the same wherever it sits in a batch."""
    torch.manual_seed(0)
    model = DiffAIL(3, 2, 2, reward_timesteps=7)
    batch = batch_of(torch.randn(6, 3), torch.randn(6, 2))
    order = torch.tensor([5, 0, 3, 1, 4, 2])
    torch.testing.assert_close(model.reward(batch[order]), model.reward(batch)[order])
    torch.testing.assert_close(model.reward(batch[:2]), model.reward(batch)[:2])


def test_discriminator_loss_is_binary_cross_entropy_of_exp_minus_l() -> None:
    loss_e, loss_p = torch.tensor([0.1, 2.0, 0.7]), torch.tensor([0.05, 3.0, 1.0])
    d_e, d_p = torch.exp(-loss_e), torch.exp(-loss_p)
    expected = F.binary_cross_entropy(d_e, torch.ones(3)) + F.binary_cross_entropy(
        d_p, torch.zeros(3)
    )
    torch.testing.assert_close(discriminator_loss(loss_e, loss_p), expected)
    # a policy the model denoises perfectly: the term is capped, not infinite
    assert discriminator_loss(torch.zeros(1), torch.zeros(1)).item() == pytest.approx(
        -math.log(1e-8), rel=1e-4
    )


@pytest.mark.parametrize(
    ("option", "words"),
    [
        ({"timesteps": 0}, "timesteps must be positive"),
        ({"beta_start": 0.1, "beta_end": 0.01}, "beta_start <= beta_end"),
        ({"reward_timesteps": 101}, "reward_timesteps must lie in 1..timesteps (100)"),
        ({"time_dim": 5}, "time_dim must be even"),
    ],
)
def test_bad_options_are_refused_by_name(option: dict, words: str) -> None:
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
        DiffAIL(3, 2, 2, **option)


def test_mish_is_torchs_mish_with_a_finite_second_derivative() -> None:
    x = torch.tensor([-1000.0, -30.0, -1.0, 0.0, 0.5, 20.0, 100.0, 1000.0], requires_grad=True)
    y = Mish()(x)
    torch.testing.assert_close(y, F.mish(x))
    (slope,) = torch.autograd.grad(y.sum(), x, create_graph=True)
    (curvature,) = torch.autograd.grad(slope.sum(), x)
    assert torch.isfinite(curvature).all()  # torch's fused Mish gives NaN above ~89


def test_mish_and_its_slope_equal_torchs_over_the_range_activations_take() -> None:
    x = torch.linspace(-60.0, 60.0, 12001, requires_grad=True)
    reference = x.detach().clone().requires_grad_(True)
    y, y_ref = Mish()(x), F.mish(reference)
    torch.testing.assert_close(y, y_ref, rtol=1e-5, atol=2e-6)
    (slope,) = torch.autograd.grad(y.sum(), x)
    (slope_ref,) = torch.autograd.grad(y_ref.sum(), reference)
    torch.testing.assert_close(slope, slope_ref, rtol=1e-5, atol=2e-6)


def test_an_update_on_policy_data_far_from_the_expert_stays_finite() -> None:
    """Policy inputs hundreds of standard deviations out (demonstrations of near-constant
    actions) saturate D to 0; the gradient penalty must not turn that into NaN weights."""
    torch.manual_seed(0)
    expert = synthetic(2.0, 200, seed=1)
    policy = synthetic(-2.0, 200, seed=2)
    far = TransitionBatch(**{**policy.__dict__, "obs": policy.obs * 300.0})
    model, metrics = train(DiffAIL(OBS, ACT, K, reward_timesteps=2), expert, far, updates=2)
    assert all(torch.isfinite(p).all() for p in model.parameters())
    assert metrics[-1]["policy_d"] == 0.0 and math.isfinite(metrics[-1]["loss"])
