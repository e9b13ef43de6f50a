"""The reward-model contract as checks any installed reward model can run, plugins included.

:data:`CHECKS` maps each check's name to a function of a registered name that returns None
(pass) or why it does not apply (skip), and raises AssertionError on failure;
``python -m qdil.rewards.contract NAME`` runs them all (:func:`main`). In a plugin's own
tests: docs/guides/write-a-reward-plugin.md (section 3).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import numpy as np
import torch
from lightning import Fabric
from ribs.archives import GridArchive

from qdil.data import Rollout, TransitionBatch
from qdil.demos.dataset import DemoSet
from qdil.rewards.base import RewardModel
from qdil.rewards.bonus import ExplorationBonus
from qdil.rewards.ebc import EBCBonus
from qdil.rewards.registry import get_reward

OBS, ACT, K = 5, 2, 2
FAST = {"giril": {"pretrain_epochs": 30}}  # keep offline pretraining short in the checks


def synthetic(center: float, size: int, seed: int) -> TransitionBatch:
    """Transitions around ``center``: observations, actions and contact patterns differ."""
    g = torch.Generator().manual_seed(seed)
    obs = center + 0.5 * torch.randn(size, OBS, generator=g)
    actions = (0.4 * np.sign(center) + 0.1 * torch.randn(size, ACT, generator=g)).clamp(-1, 1)
    contacts = torch.tensor([[1.0, 0.0] if center > 0 else [0.0, 1.0]]).repeat(size, 1)
    next_obs = center + 0.5 * torch.randn(size, OBS, generator=g)
    dones = torch.zeros(size)
    dones[-1] = 1.0
    return TransitionBatch(
        obs, actions, contacts, next_obs, contacts.clone(), dones, torch.full((size,), -1.0)
    )


def demos_of(batch: TransitionBatch) -> DemoSet:
    """A two-episode demonstration set holding ``batch``."""
    n = len(batch)
    return DemoSet(
        task="Walker2d-v5",
        obs=batch.obs.double().numpy(),
        actions=batch.actions.double().numpy(),
        contacts=batch.contacts.numpy(),
        rewards=np.zeros(n),
        next_obs=batch.next_obs.double().numpy(),
        next_contacts=batch.next_contacts.numpy(),
        episode_ends=np.array([n // 2, n]),
        terminated=np.array([True, False]),
    )


def as_rollout(batch: TransitionBatch, envs: int = 1) -> Rollout:
    """Transitions laid out time-major, (len / envs, envs)."""
    steps = len(batch) // envs

    def tm(x: torch.Tensor) -> torch.Tensor:
        return x[: steps * envs].reshape(envs, steps, *x.shape[1:]).transpose(0, 1).contiguous()

    starts = torch.zeros(steps, envs)
    starts[0] = 1.0
    return Rollout(
        obs=tm(batch.obs),
        actions=tm(batch.actions),
        contacts=tm(batch.contacts),
        next_obs=tm(batch.next_obs),
        next_contacts=tm(batch.next_contacts),
        rewards=torch.randn(steps, envs),
        dones=tm(batch.dones),
        terminated=tm(batch.dones),
        log_probs=tm(batch.log_probs),
        valid=torch.ones(steps, envs),
        starts=starts,
    )


def train(model: RewardModel, expert: TransitionBatch, policy: TransitionBatch, updates: int):
    """Set ``model`` up as the QD loop does (Fabric, demos, pretraining) and update it.

    Returns:
        The model and the metrics of each update.
    """
    if model.learned:
        optimizers = model.configure_optimizers()
        optimizers = optimizers if isinstance(optimizers, list) else [optimizers]
        Fabric(accelerator="cpu", devices=1).setup(model, *optimizers)
    demos = demos_of(expert) if model.needs_demos else None
    model.setup(demos)
    model.pretrain(demos)
    metrics = (
        [model.update(expert, policy, iteration=i) for i in range(updates)] if model.learned else []
    )
    return model, metrics


def expect(condition: object, message: str) -> None:
    """Raise AssertionError with ``message`` unless ``condition`` (kept under ``python -O``)."""
    if not condition:
        raise AssertionError(message)


def make(name: str) -> RewardModel:
    """The registered model ``name`` on the synthetic sizes, seeded."""
    torch.manual_seed(0)
    return get_reward(name)(OBS, ACT, K, **FAST.get(name, {}))


def trained(name: str, updates: int) -> RewardModel:
    """``name`` after ``updates`` updates on the synthetic expert and policy data."""
    model, metrics = train(make(name), expert_data(), policy_data(), updates)
    bad = [f"{k}={v}" for m in metrics for k, v in m.items() if not np.isfinite(v)]
    expect(not bad, f"{name}: non-finite update metrics: {', '.join(bad)}")
    return model


def expert_data() -> TransitionBatch:
    """The checks' expert transitions (around +2), the same on every call."""
    return synthetic(2.0, 400, seed=1)


def policy_data() -> TransitionBatch:
    """The checks' policy transitions (around −2), the same on every call."""
    return synthetic(-2.0, 400, seed=2)


def rewards_have_shape_dtype_and_are_finite(name: str) -> str | None:
    """Rewards from ``predict_reward`` have shape (T, N), dtype float32, and are finite."""
    model = trained(name, updates=1)
    rewards = model.predict_reward(as_rollout(policy_data(), envs=4), update=True)
    expect(rewards.shape == (100, 4), f"{name}: rewards of shape {tuple(rewards.shape)}")
    expect(rewards.dtype == torch.float32, f"{name}: rewards of dtype {rewards.dtype}")
    expect(torch.isfinite(rewards).all(), f"{name}: non-finite rewards")
    return None


def training_reaches_every_parameter(name: str) -> str | None:
    """Three updates change every parameter (one the loss never reaches fails it)."""
    before = {k: v.detach().clone() for k, v in make(name).named_parameters()}
    if not before:
        return f"{name} has no parameters"
    model = trained(name, updates=3)
    for key, value in model.named_parameters():
        expect(not torch.equal(value.detach(), before[key]), f"{name}: {key} never changed")
    return None


def tells_expert_from_non_expert_transitions(name: str) -> str | None:
    """After 40 updates, held-out expert transitions get a higher mean reward.

    Lower for a curiosity reward (``prefers_expert = False``); skipped for ``None``.
    """
    model = trained(name, updates=40)
    if model.prefers_expert is None:
        return f"{name} does not compare transitions (prefers_expert = None)"
    held_out_e, held_out_p = synthetic(2.0, 200, seed=5), synthetic(-2.0, 200, seed=6)
    r_e = model.predict_reward(as_rollout(held_out_e)).mean()
    r_p = model.predict_reward(as_rollout(held_out_p)).mean()
    if model.prefers_expert:
        expect(r_e > r_p, f"{name}: expert {r_e:.3f} <= policy {r_p:.3f}")
    else:
        expect(r_e < r_p, f"{name}: curiosity reward should be lower on the expert")
    return None


def state_survives_a_checkpoint_round_trip(name: str) -> str | None:
    """``state_dict()`` and ``extra_state()`` loaded into a fresh model reproduce the rewards."""
    model = trained(name, updates=2)
    rollout = as_rollout(policy_data(), envs=2)
    model.predict_reward(rollout, update=True)  # stateful models build state
    state, extra = model.state_dict(), model.extra_state()
    expected = model.predict_reward(rollout, update=True)
    copy = make(name)
    if copy.needs_demos:
        copy.setup(demos_of(expert_data()))
    copy.load_state_dict(state)
    copy.load_extra_state(extra)
    torch.testing.assert_close(copy.predict_reward(rollout, update=True), expected)
    return None


def works_under_the_exploration_bonus(name: str) -> str | None:
    """Under the bonus (weight 2) the added reward lies in [1, 2) and the flags pass through."""
    model = trained(name, updates=1)
    wrapped = ExplorationBonus(model, weight=2.0)
    rollout = as_rollout(policy_data(), envs=4)
    extra = wrapped.predict_reward(rollout) - model.predict_reward(rollout)
    expect(torch.all((extra >= 1.0) & (extra < 2.0)), f"{name}: bonus outside [1, 2)")
    expect(wrapped.learned == model.learned, f"{name}: the bonus changed learned")
    expect(wrapped.needs_demos == model.needs_demos, f"{name}: the bonus changed needs_demos")
    return None


def works_under_the_ebc_bonus(name: str) -> str | None:
    """Under EBC (q = 2, p = 0.5) training windows get 2.5 (empty cell) or 0.5 (occupied).

    Evaluations get nothing, and the flags pass through.
    """
    model = trained(name, updates=1)
    archive = GridArchive(solution_dim=1, dims=[10] * K, ranges=[(0.0, 1.0)] * K)
    archive.add(np.zeros((1, 1)), np.zeros(1), np.array([[0.05, 0.95]]))  # the policy's cell
    wrapped = EBCBonus(model, lambda: archive, weight=2.0, offset=0.5)
    policy = as_rollout(policy_data(), envs=4)  # contacts (0, 1) at every step: occupied
    expert = as_rollout(expert_data(), envs=4)  # contacts (1, 0): an empty cell
    for rollout, expected in ((policy, 0.5), (expert, 2.5)):
        extra = wrapped.predict_reward(rollout, update=True) - model.predict_reward(rollout)
        torch.testing.assert_close(extra, torch.full_like(extra, expected), atol=1e-5, rtol=0)
    extra = wrapped.predict_reward(expert) - model.predict_reward(expert)
    expect(torch.all(extra == 0), f"{name}: the EBC bonus reached an evaluation")
    expect(wrapped.learned == model.learned, f"{name}: the EBC bonus changed learned")
    expect(wrapped.needs_demos == model.needs_demos, f"{name}: EBC changed needs_demos")
    return None


# Each check takes a registered name; it returns None when it passes, a note when it does
# not apply to the model, and raises AssertionError naming what failed.
CHECKS: dict[str, Callable[[str], str | None]] = {
    check.__name__: check
    for check in (
        rewards_have_shape_dtype_and_are_finite,
        training_reaches_every_parameter,
        tells_expert_from_non_expert_transitions,
        state_survives_a_checkpoint_round_trip,
        works_under_the_exploration_bonus,
        works_under_the_ebc_bonus,
    )
}


def main(argv: list[str] | None = None) -> int:
    """``python -m qdil.rewards.contract NAME...``: run every check; 1 if any failed."""
    parser = argparse.ArgumentParser(
        prog="python -m qdil.rewards.contract",
        description="Run qdil's reward-model contract checks on registered models (built-ins, "
        "installed plugins, and local plugin folders: ./plugins and $QDIL_PLUGIN_PATH).",
    )
    parser.add_argument("names", nargs="+", metavar="NAME", help="registered reward names")
    args = parser.parse_args(argv)
    failed = 0
    for name in args.names:
        try:
            get_reward(name)
        # an unknown name (the message lists the known ones) or a missing plugin folder
        except (ValueError, FileNotFoundError) as error:
            parser.error(str(error))
        for label, check in CHECKS.items():
            try:
                note = check(name)
            except AssertionError as error:
                failed += 1
                print(f"FAIL {name} {label}: {error}")
                continue
            print(f"SKIP {name} {label}: {note}" if note else f"PASS {name} {label}")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
