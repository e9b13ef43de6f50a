"""How much a measure-conditioned critic of a run leans on the contact flags δ(s).

mCWAE-WGAIL reads x = (s, a, δ(s)): the foot-contact flags are part of its input. If the
critic rewarded the demonstrations' own contact patterns, a policy with another gait would
lose reward for its pattern alone, and the exploration bonus, which pays for new patterns,
would pull against it. This script loads the reward model of a run's last checkpoint and
scores every demonstration transition twice: with its own flags, and with the flags of
each pattern in turn (both feet up, one foot down, both down) for all of them. A shift of
the mean score, in units of the critic's spread on the policy's data (σ_π, what
``reward_form: standardized`` divides by), says how much reward the pattern alone is worth;
beside it stands the expert–policy gap (μ_e − μ_π) / σ_π the critic keeps between the
demonstrations and the policy.

Usage::

    python benchmarks/probes/reward_contacts.py runs/walker_mcwae-seed0 [RUN ...] [--demos walker2d]

Runs whose reward model does not read δ(s) (``use_measures: false``) are skipped. Works
for the WAE critics (``critic_means``, ``critic_policy_std``); one thread, seconds per run.
"""

from __future__ import annotations

import argparse
import importlib
import itertools
from dataclasses import replace
from pathlib import Path

import torch
import yaml

from qdil.demos.io import load_demos
from qdil.files import CONFIG_NAME
from qdil.qd.checkpoint import CHECKPOINT, read_checkpoint


def load_reward(run_dir: Path, sizes: tuple[int, int, int]) -> tuple[torch.nn.Module, int]:
    """The reward model of ``run_dir``'s last checkpoint (the bonus left out), and its iteration."""
    config = yaml.safe_load((run_dir / CONFIG_NAME).read_text())["reward"]
    module, _, name = config["class_path"].rpartition(".")
    model = getattr(importlib.import_module(module), name)(*sizes, **config["init_args"])
    checkpoint = read_checkpoint(run_dir / CHECKPOINT)
    state = checkpoint["reward"]["state_dict"]
    # with the bonus on, the checkpoint holds ExplorationBonus, whose ``model`` is the reward
    if any(key.startswith("model.") for key in state):
        state = {key[6:]: value for key, value in state.items() if key.startswith("model.")}
    model.load_state_dict(state)
    return model.eval(), checkpoint["iteration"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run directories with a checkpoint")
    parser.add_argument("--demos", default="walker2d", help="the runs' demonstrations")
    args = parser.parse_args()
    torch.set_num_threads(1)

    expert = load_demos(args.demos).transitions()
    sizes = expert.obs.shape[1], expert.actions.shape[1], expert.contacts.shape[1]
    own = expert.contacts.round()
    patterns = list(itertools.product((0.0, 1.0), repeat=sizes[2]))
    print(f"{len(expert)} demonstration transitions of {args.demos}; scores in units of σ_π\n")
    print(
        "| run | iteration | (μ_e − μ_π) / σ_π | pattern δ | share of demo steps | "
        "their own score − mean | all flags set to δ: shift of the mean |"
    )
    print("|---|---|---|---|---|---|---|")
    for run_dir in args.runs:
        model, iteration = load_reward(run_dir, sizes)
        if not getattr(model, "use_measures", False):
            print(f"| {run_dir} | – | – | does not read δ(s) | | | |")
            continue
        expert_mean, policy_mean = model.critic_means.tolist()
        spread = float(model.critic_policy_std)
        with torch.no_grad():
            base = model.score(expert)
            mean = base.mean()
            for i, pattern in enumerate(patterns):
                flags = torch.tensor(pattern)
                shift = (
                    model.score(replace(expert, contacts=flags.expand_as(own).clone())).mean()
                    - mean
                ) / spread
                mask = (own == flags).all(1)
                theirs = (base[mask].mean() - mean) / spread if mask.any() else float("nan")
                head = (
                    f"{run_dir} | {iteration} | {(expert_mean - policy_mean) / spread:.2f}"
                    if i == 0
                    else " | |"
                )
                share = float(mask.float().mean())
                print(
                    f"| {head} | {tuple(int(p) for p in pattern)} | {share:.2f} "
                    f"| {float(theirs):+.2f} | {float(shift):+.2f} |"
                )


if __name__ == "__main__":
    main()
