"""Does a trained reward tell a good action from a bad one in the same state?

PPO credits actions through the reward: an imitation reward that depends on the state alone
says where to be but not what to do there. This script trains reward models offline, as
``qdil fit`` builds them, on the expert demonstrations against a "policy" made of the same
expert states with noisy actions (a + σ·N(0, 1), clipped to the action space), then scores
held-out perturbations of every expert transition (a + u·N(0, 1), u uniform in [0, 1], so
that the action errors cover a range) and reports Spearman's ρ between the reward and the
negative action error: 1 when the reward orders actions exactly by their distance to the
expert's, 0 when it ignores them.

Usage::

    python benchmarks/probes/reward_actions.py gail:batch_size=120 \\
        "mcwae_wgail:batch_size=120,reward_form=standardized" \\
        "mcwae_wgail:batch_size=120,reward_form=standardized,latent_dim=32" --sigma 0.5

A model is a registered reward name with ``key=value`` options after a colon, as in
``benchmarks/probes/reward_ranking.py``.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import torch
from reward_ranking import parse_model, train
from scipy.stats import spearmanr

from qdil.demos.io import load_demos


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("models", nargs="+", help="name[:key=value,...] of reward models")
    parser.add_argument("--demos", default="walker2d", help="expert demonstrations")
    parser.add_argument("--sigma", type=float, default=0.5, help="the policy's action noise")
    parser.add_argument("--updates", type=int, default=60, help="reward updates (QD iterations)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    torch.set_num_threads(1)

    demos = load_demos(args.demos)
    expert = demos.transitions()
    generator = torch.Generator().manual_seed(args.seed)
    noise = args.sigma * torch.randn(expert.actions.shape, generator=generator)
    policy = replace(expert, actions=(expert.actions + noise).clamp(-1.0, 1.0))
    scale = torch.rand(len(expert), 1, generator=generator)
    perturbed = expert.actions + scale * torch.randn(expert.actions.shape, generator=generator)
    probe = replace(expert, actions=perturbed.clamp(-1.0, 1.0))
    error = (probe.actions - expert.actions).norm(dim=1).numpy()
    print(
        f"{len(expert)} expert transitions of {demos.task}; policy: expert states, actions + "
        f"{args.sigma}·N(0, 1); {args.updates} updates\n"
    )
    print("| model | ρ(reward, −action error) | expert / step | policy / step | seconds |")
    print("|---|---|---|---|---|")
    for spec in args.models:
        name, options = parse_model(spec)
        start = time.perf_counter()
        model = train(name, options, demos, policy, args.updates, args.seed)
        with torch.no_grad():
            rewards = model.reward(probe).double().numpy()
            on_expert = float(model.reward(expert).mean())
            on_policy = float(model.reward(policy).mean())
        rho = spearmanr(rewards, -error).statistic
        print(
            f"| {spec} | {rho:+.3f} | {on_expert:.3f} | {on_policy:.3f} "
            f"| {time.perf_counter() - start:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
