"""The QD baselines' recipes, written by ``generate.py``: CMA-MAEGA (ES) and sep-CMA-MAE.

Settings from dqd-rl's CMA-MEGA (ES) and scaling-cma-mae's sep-CMA-MAE
(``../shared/reference/qd_baselines.md``); the budget is PPGA's laptop budget in env steps
(``qd.env_steps``), so that the methods compare at equal cost.
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


# sep-CMA-MAE's threshold floor: the origin sets the task's lowest score, so that every
# solution enters; returns here stay above 0 on Walker2d and Humanoid (a healthy reward per
# step) and above -1000 on HalfCheetah (its control cost over 1,000 steps)
SEP_THRESHOLD = {"walker": 0.0, "halfcheetah": -1000.0, "humanoid": 0.0}


def sep_cma_mae(task: str, gym_id: str, bandit: bool) -> tuple[str, dict]:
    """sep-CMA-MAE: gradient-free separable CMA-ES emitters over the policies' parameters."""
    emitters = 10 if bandit else 5
    lines = [
        f"sep-CMA-MAE on {gym_id} with the true reward: a QD baseline of the PPGA paper.",
        "No gradient estimator (rl: null): 5 emitters of separable CMA-ES over every",
        "policy parameter (sigma0 0.02, 40 solutions each, mu selection by improvement,",
        "restart at an elite on the strategy's own stop), archive learning rate 0.001 over a",
        f"threshold floor of {SEP_THRESHOLD[task]:g}: scaling-cma-mae's sep-CMA-MAE settings.",
        f"Budget: {PPGA_ENV_STEPS[task]:,} env steps, the laptop PPGA recipe's (qd.env_steps).",
        "Policies play with fixed observation statistics, as the origin runs without",
        "observation normalisation (docs/concepts/seats.md).",
    ]
    if bandit:
        lines[1] = "No gradient estimator (rl: null): a bandit (pyribs' BanditScheduler, UCB1)"
        lines[2] = "keeps 5 of a pool of 10 separable CMA-ES emitters active (sigma0 0.02, 40"
        lines[3] = "solutions each, mu selection by improvement, restart on the strategy's stop),"
        lines[4] = (
            "archive learning rate 0.001 over a threshold floor of "
            f"{SEP_THRESHOLD[task]:g} (scaling-cma-mae's settings)."
        )
    qd: dict = {
        "iterations": 100_000,
        "env_steps": PPGA_ENV_STEPS[task],
        "cells": 50,
        "archive_learning_rate": 0.001,
        "threshold_min": SEP_THRESHOLD[task],
        "branch_episodes": 1,
        "mean_episodes": 1,
        "emitter": {
            "class_path": "qdil.qd.EvolutionStrategyEmitter",
            "init_args": {
                "sigma0": 0.02,
                "batch_size": 40,
                "es": "sep_cma_es",
                "ranker": "imp",
                "selection_rule": "mu",
                "restart_rule": "basic",
            },
        },
        "emitters": emitters,
        "deterministic_eval": True,
    }
    if bandit:
        qd["scheduler"] = {
            "class_path": "ribs.schedulers.BanditScheduler",
            "init_args": {"num_active": 5, "zeta": 0.05, "reselect": "terminated"},
        }
    body = {
        "seed": 0,
        "reward": "true_reward",
        "env": {"task": gym_id, "num_envs": 3},
        "rl": None,
        "qd": qd,
        "logging": {"checkpoint_every": 20},
    }
    return _comment(lines), body


def baseline_files(here: Path, tasks: dict[str, str], ppga: dict[str, dict]) -> dict[Path, str]:
    """recipes/TASK_{cma_maega_es,sep_cma_mae,sep_cma_mae_bandit}.yaml: path -> text."""
    out = {}
    for task, gym_id in tasks.items():
        recipes = {
            "cma_maega_es": cma_maega_es(task, gym_id, ppga[task]["archive_learning_rate"]),
            "sep_cma_mae": sep_cma_mae(task, gym_id, bandit=False),
            "sep_cma_mae_bandit": sep_cma_mae(task, gym_id, bandit=True),
        }
        for stem, (text, body) in recipes.items():
            out[here / f"{task}_{stem}.yaml"] = text + yaml.safe_dump(body, sort_keys=False)
    return out
