"""The QD baselines' recipes (``TASK_cma_maega_es.yaml``), written by ``generate.py``.

Settings from dqd-rl's CMA-MEGA (ES) (``../shared/reference/qd_baselines.md``); the archive
(cells, learning rate, threshold) is the task's PPGA recipe's, and the budget is PPGA's
laptop budget in env steps (``qd.env_steps``), so that the methods compare at equal cost.
"""

from __future__ import annotations

from pathlib import Path

import yaml

# env steps of each task's laptop PPGA recipe: Walker2d as measured over 120 iterations
# (2.00e7 to 2.09e7, runs/search seeds 5-6); HalfCheetah exactly (its episodes never end
# early): 200 x (2 x 10 x 128 x 96 + 64 x 1000 + 8 x 1000); Humanoid at most, as if no
# episode ended early: 100 x (2 x 10 x 128 x 48 + 32 x 1000 + 8 x 1000)
PPGA_ENV_STEPS = {"walker": 20_000_000, "halfcheetah": 63_552_000, "humanoid": 16_288_000}


def _comment(lines: list[str]) -> str:
    return "".join(f"# {line}\n" for line in lines)


def cma_maega_es(task: str, gym_id: str, archive_learning_rate: float) -> tuple[str, dict]:
    """CMA-MAEGA (ES): PPGA's emitter over OpenAI-ES gradients, on the true reward."""
    lines = [
        f"CMA-MAEGA (ES) on {gym_id} with the true reward: a QD baseline of the PPGA paper.",
        "Gradients of the objective and both measures from 50 mirrored pairs of perturbed",
        "policies (sigma 0.02, one episode each, centred ranks, unit rows: dqd-rl's CMA-MEGA",
        "(ES)); CMA-ES over the 3 coefficients from a zero mean (sigma_g 1.0), 100 branches",
        "ranked new cell > improvement (2imp), restart when none improved; theta steps to",
        "theta + sum_j mu_j g_j (docs/concepts/es-gradients.md).",
        f"Budget: {PPGA_ENV_STEPS[task]:,} env steps, the laptop PPGA recipe's (qd.env_steps).",
        "Archive as the PPGA recipe's (cells, learning rate, threshold); no training",
        "simulations are stepped (env.num_envs only sizes the reward model).",
    ]
    body = {
        "seed": 0,
        "reward": "true_reward",
        "env": {"task": gym_id, "num_envs": 3},
        "rl": {
            "class_path": "qdil.qd.ESGradients",
            "init_args": {"pairs": 50, "sigma": 0.02, "episodes": 1},
        },
        "qd": {
            "iterations": 100_000,
            "env_steps": PPGA_ENV_STEPS[task],
            "cells": 50,
            "archive_learning_rate": archive_learning_rate,
            "threshold_min": 200.0,
            "branch_episodes": 1,
            "mean_episodes": 1,
            "emitter": {
                "class_path": "qdil.qd.PPGAEmitter",
                "init_args": {
                    "batch_size": 100,
                    "sigma0": 1.0,
                    "es": "cma_es",
                    "ranker": "2imp",
                    "initial_mean": "zero",
                    "restart_rule": "no_improvement",
                },
            },
            "deterministic_eval": True,
        },
        "logging": {"checkpoint_every": 20},
    }
    return _comment(lines), body


def baseline_files(here: Path, tasks: dict[str, str], ppga: dict[str, dict]) -> dict[Path, str]:
    """recipes/TASK_cma_maega_es.yaml for every task: path -> text."""
    out = {}
    for task, gym_id in tasks.items():
        text, body = cma_maega_es(task, gym_id, ppga[task]["archive_learning_rate"])
        out[here / f"{task}_cma_maega_es.yaml"] = text + yaml.safe_dump(body, sort_keys=False)
    return out
