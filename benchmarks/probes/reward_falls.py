"""Which part of a run's reward pays the steps before a fall: the learned model or the bonus.

The survival figures (docs/concepts/survival.md) say whether the rewards handed to RL pay
the last 20 steps before a fall more than other steps, not which part does. This script
loads a run's last checkpoint (the reward model, its exploration bonus's visit counts and
its absorbing floor as trained), replays elites of its true-keyed archive once each with
mean actions, scores every step with the model and with the bonus apart, and prints each
part's reward per step before a fall and elsewhere, with the contact patterns behind the
bonus.

Usage::

    python benchmarks/probes/reward_falls.py RUN [RUN ...] [--elites 128] [--demos humanoid]

One thread, about a minute per run on Humanoid.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

import numpy as np
import torch
import yaml

from qdil.demos.io import load_demos
from qdil.envs.faces import torch_face
from qdil.evaluation.rescore import ReplaySettings, elite_policies
from qdil.files import CONFIG_NAME
from qdil.qd.checkpoint import CHECKPOINT, load_archive, read_checkpoint
from qdil.qd.survival import WINDOW, before_termination
from qdil.rewards.bonus import ExplorationBonus
from qdil.rl.episodes import evaluate_policies

PARTS = ("model", "bonus", "true")


def load_reward(run_dir: Path, sizes: tuple[int, int, int]) -> tuple[torch.nn.Module, int]:
    """The reward handed to RL by ``run_dir``'s last checkpoint (bonus included), and its iteration.

    Raises:
        ValueError: the run's bonus is not the single-step archive bonus this script splits.
    """
    config = yaml.safe_load((run_dir / CONFIG_NAME).read_text())
    module, _, name = config["reward"]["class_path"].rpartition(".")
    model = getattr(importlib.import_module(module), name)(*sizes, **config["reward"]["init_args"])
    bonus = config.get("bonus") or {}
    if bonus.get("enabled") and bonus.get("type", "single_step") != "single_step":
        raise ValueError(f"{run_dir}: bonus.type {bonus['type']!r}; only single_step is split")
    if bonus.get("enabled"):
        model = ExplorationBonus(model, weight=bonus["weight"], cells=bonus.get("cells"))
    checkpoint = read_checkpoint(run_dir / CHECKPOINT)
    model.load_state_dict(checkpoint["reward"]["state_dict"])
    return model.eval(), checkpoint["iteration"]


def replay(run_dir: Path, reward: torch.nn.Module, elites: int) -> dict[str, np.ndarray]:
    """Per-step parts of ``elites`` elites' episodes, spread evenly over the archive by row.

    Returns:
        ``model``, ``bonus``, ``true`` (per-step rewards), ``near`` (within :data:`WINDOW`
        steps of a termination), ``far`` (other steps), ``pattern`` (contact pattern as an
        integer, bit i foot i), each (S,) over the valid steps; ``falls`` and ``elites``.
    """
    settings = ReplaySettings.of_run(run_dir)
    archive, _ = load_archive(run_dir, "true")
    data = archive.data()
    count = len(data["objective"])
    rows = np.unique(np.linspace(0, count - 1, min(elites, count)).round().astype(int))
    env = settings.make_env(len(rows), num_threads=1)
    actor, stats = elite_policies(data, rows, env, settings.actor_hidden)
    parts: dict[str, list[torch.Tensor]] = {key: [] for key in (*PARTS, "near", "far", "pattern")}
    falls = []

    def score(rollout) -> torch.Tensor:  # the reward_fn of evaluate_policies
        with torch.no_grad():
            bonus = reward.added(rollout, False) if isinstance(reward, ExplorationBonus) else None
            inner = reward.model if isinstance(reward, ExplorationBonus) else reward
            model = inner.predict_reward(rollout)
        valid = rollout.valid > 0
        near = before_termination(rollout.dones, rollout.terminated, WINDOW) & valid
        bits = 2 ** torch.arange(rollout.contacts.shape[-1])
        pattern = ((rollout.contacts > 0.5).long() * bits).sum(-1)
        values = {
            "model": model,
            "bonus": torch.zeros_like(model) if bonus is None else bonus,
            "true": rollout.rewards,
        }
        for key, value in values.items():
            parts[key].append(value[valid].double())
        parts["near"].append(near[valid])
        parts["far"].append((valid & ~near)[valid])
        parts["pattern"].append(pattern[valid])
        falls.append(int(((rollout.terminated > 0) & valid).sum()))
        return model + values["bonus"]

    evaluate_policies(torch_face(env), actor, stats, 1, 0, score, True, settings.obs_clip)
    out = {key: torch.cat(value).numpy() for key, value in parts.items()}
    out["falls"], out["elites"] = np.array(sum(falls)), np.array(len(rows))
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run directories with a checkpoint")
    parser.add_argument("--elites", type=int, default=128, help="elites replayed per run")
    parser.add_argument("--demos", default="humanoid", help="the runs' demonstrations")
    args = parser.parse_args(argv)
    for run_dir in args.runs:
        if not (run_dir / CHECKPOINT).is_file():
            parser.error(f"{run_dir}: no checkpoint at {run_dir / CHECKPOINT}")
    torch.set_num_threads(1)
    expert = load_demos(args.demos).transitions()
    sizes = expert.obs.shape[1], expert.actions.shape[1], expert.contacts.shape[1]
    print(
        f"per-step means over the last {WINDOW} steps before a fall (near) and all other "
        "steps (far); one deterministic episode per elite\n"
    )
    print(
        "| run | iteration | elites | falls | floor | model near | model far | bonus near "
        "| bonus far | true near | true far |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    patterns = []
    for run_dir in args.runs:
        reward, iteration = load_reward(run_dir, sizes)
        inner = reward.model if isinstance(reward, ExplorationBonus) else reward
        floor = getattr(inner, "absorbing_floor", None)
        steps = replay(run_dir, reward, args.elites)
        near, far = steps["near"], steps["far"]
        cells = [f"{steps[p][near].mean():.3f} | {steps[p][far].mean():.3f}" for p in PARTS]
        floor_text = "–" if floor is None else f"{float(floor):.3f}"
        print(
            f"| {run_dir.name} | {iteration} | {int(steps['elites'])} | {int(steps['falls'])} "
            f"| {floor_text} | {' | '.join(cells)} |"
        )
        for pattern in np.unique(steps["pattern"]):
            share = [float((steps["pattern"][m] == pattern).mean()) for m in (near, far)]
            patterns.append((run_dir.name, int(pattern), *share))
    print("\ncontact patterns (bit i: foot i on the ground), share of steps near and far\n")
    print("| run | pattern | near | far |\n|---|---|---|---|")
    for name, pattern, near_share, far_share in patterns:
        print(f"| {name} | {pattern:02b} | {near_share:.3f} | {far_share:.3f} |")


if __name__ == "__main__":
    sys.exit(main())
