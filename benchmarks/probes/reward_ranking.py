"""How well a trained reward model ranks episodes of known quality by their true reward.

An imitation reward is useful to QD only if it orders behaviour as the true reward does:
the archive and xNES rank branches by learned return. This script trains reward models
offline on the expert demonstrations against a pool of episodes of varied quality (made
from an expert run's archive with ``qdil demos``), then compares, over the pool's
episodes, the mean learned reward per step with the mean true reward per step (Spearman's
ρ; per step, so that episode length, which every positive reward counts, does not decide).

Make a pool of 48 episodes from the whole archive of an expert run, then score models::

    qdil demos runs/walker_ppga-seed0 --top 100000 --num 48 --out pool.npz
    python benchmarks/probes/reward_ranking.py pool.npz gail \\
        "mcwae_wgail:reward_form=calibrated" "mcwae_wgail:reward_form=standardized"

A model is a registered reward name with ``key=value`` options after a colon, separated by
commas. The models train against the pool's weaker half (``--policy weak``, as an imitation
run trains against its own, weaker, policy) or the whole pool (``--policy all``).
"""

from __future__ import annotations

import argparse
import time

import lightning as L
import numpy as np
import torch
from scipy.stats import spearmanr

from qdil.data import TransitionBatch
from qdil.demos.io import load_demos
from qdil.rewards.registry import get_reward


def parse_model(spec: str) -> tuple[str, dict[str, object]]:
    """``name:key=value,...`` to (name, options), numbers parsed as numbers."""
    name, _, text = spec.partition(":")
    options: dict[str, object] = {}
    for item in filter(None, text.split(",")):
        key, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"model option {item!r} of {spec!r}: write key=value")
        for cast in (int, float):
            try:
                options[key] = cast(value)
                break
            except ValueError:
                continue
        else:
            options[key] = value
    return name, options


def train(name: str, options: dict, demos, policy: TransitionBatch, updates: int, seed: int):
    """A reward model built as ``qdil fit`` builds it, after ``updates`` updates."""
    torch.manual_seed(seed)
    expert = demos.transitions()
    sizes = expert.obs.shape[1], expert.actions.shape[1], expert.contacts.shape[1]
    model = get_reward(name)(*sizes, **options)
    optimizers = model.configure_optimizers() if model.learned else None
    if optimizers is not None:
        optimizers = optimizers if isinstance(optimizers, list | tuple) else [optimizers]
        L.Fabric(accelerator="cpu", devices=1).setup(model, *optimizers)
    model.setup(demos)
    model.pretrain(demos)
    generator = torch.Generator().manual_seed(seed)
    for iteration in range(updates if model.learned else 0):
        model.update(expert, policy.sample(min(6144, len(policy)), generator), iteration)
    return model


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("pool", help="episodes of varied quality (.npz from `qdil demos`)")
    parser.add_argument("models", nargs="+", help="name[:key=value,...] of reward models")
    parser.add_argument("--demos", default="walker2d", help="expert demonstrations")
    parser.add_argument("--updates", type=int, default=30, help="reward updates (QD iterations)")
    parser.add_argument("--policy", choices=("weak", "all"), default="weak")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    demos = load_demos(args.demos)
    pool = load_demos(args.pool, task=demos.task)
    starts, lengths, returns = pool.episode_starts, pool.lengths, pool.returns
    episodes = [torch.arange(s, s + n) for s, n in zip(starts, lengths, strict=True)]
    order = np.argsort(returns)
    chosen = order[: len(order) // 2] if args.policy == "weak" else order
    transitions = pool.transitions()
    policy = transitions[torch.cat([episodes[e] for e in chosen])]
    true_per_step = returns / lengths
    tail = max(1, len(order) // 4)
    print(
        f"pool: {len(returns)} episodes, returns {returns.min():.0f} to {returns.max():.0f}; "
        f"trained against the {'weaker half' if args.policy == 'weak' else 'whole pool'}, "
        f"{args.updates} updates\n"
    )
    print(
        "| model | ρ per step | ρ of returns | expert / step | best quarter / step "
        "| worst quarter / step | seconds |"
    )
    print("|---|---|---|---|---|---|---|")
    for spec in args.models:
        name, options = parse_model(spec)
        start = time.perf_counter()
        model = train(name, options, demos, policy, args.updates, args.seed)
        with torch.no_grad():
            rewards = model.reward(transitions).double().numpy()
            expert = float(model.reward(demos.transitions()).mean())
        per_step = np.array([rewards[e.numpy()].mean() for e in episodes])
        rho_step = spearmanr(per_step, true_per_step).statistic
        rho_return = spearmanr(per_step * lengths, returns).statistic
        print(
            f"| {spec} | {rho_step:+.3f} | {rho_return:+.3f} | {expert:.3f} "
            f"| {per_step[order[-tail:]].mean():.3f} | {per_step[order[:tail]].mean():.3f} "
            f"| {time.perf_counter() - start:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
