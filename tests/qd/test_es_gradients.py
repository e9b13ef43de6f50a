"""ES gradients: OpenAI-ES's centred ranks and mirrored estimate, the CMA-MAEGA (ES) run
from YAML (resumed bit for bit, the reward model trained on the perturbation episodes)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from run_rows import rows

from qdil.cli import main
from qdil.qd import ESGradients
from qdil.qd.es_gradients import centered_ranks, es_gradients
from qdil.rl.normalize import RunningMeanStd
from qdil.seats import GradientEstimator

ROOT = Path(__file__).resolve().parents[2]


def openai_centered_ranks(x: np.ndarray) -> np.ndarray:
    """openai/evolution-strategies-starter's ``compute_centered_ranks``, as published."""
    ranks = np.empty(x.size, dtype=int)
    ranks[x.ravel().argsort()] = np.arange(x.size)
    y = ranks.reshape(x.shape).astype(np.float32)
    y /= x.size - 1
    y -= 0.5
    return y


def test_centered_ranks_equal_openai_es_per_objective(rng) -> None:
    scores = rng.normal(size=(40, 3))
    ours = centered_ranks(scores)
    for j in range(3):
        np.testing.assert_allclose(ours[:, j], openai_centered_ranks(scores[:, j]), atol=1e-7)
    assert ours.min() == -0.5 and ours.max() == 0.5


def test_the_mirrored_estimate_is_the_formula_and_follows_a_linear_objective(rng) -> None:
    n, d, sigma = 300, 20, 0.05
    theta, slopes = rng.normal(size=d), rng.normal(size=(2, d))
    epsilon = rng.standard_normal((n, d))
    plus, minus = (theta + sigma * epsilon) @ slopes.T, (theta - sigma * epsilon) @ slopes.T
    ranks = centered_ranks(np.concatenate([plus, minus]))
    formula = (ranks[:n] - ranks[n:]).T @ epsilon / (n * sigma)
    np.testing.assert_allclose(es_gradients(epsilon, plus, minus, sigma, False), formula)
    unit = es_gradients(epsilon, plus, minus, sigma, True)
    np.testing.assert_allclose(np.linalg.norm(unit, axis=1), 1.0, rtol=1e-6)
    for row, slope in zip(unit, slopes, strict=True):  # points along each objective's slope
        assert row @ slope / np.linalg.norm(slope) > 0.9


def test_the_walk_steps_along_the_estimate_and_not_from_a_restarted_theta(rng) -> None:
    estimator = ESGradients()
    assert issubclass(ESGradients, GradientEstimator) and estimator.eval_slots == 100
    theta = rng.normal(size=5).astype(np.float32)
    estimator._at, estimator._gradients = theta.astype(np.float64), rng.normal(size=(3, 5))
    stats, c = RunningMeanStd(1, (3,)), np.array([1.0, -0.5, 0.25])
    moved = estimator.walk(theta, stats, c, None, 0).solutions[0]
    np.testing.assert_allclose(moved, theta + c @ estimator._gradients)
    restarted = theta + 1.0
    assert np.array_equal(estimator.walk(restarted, stats, c, None, 0).solutions[0], restarted)


@pytest.mark.parametrize(("key", "value"), [("pairs", 0), ("episodes", 0), ("sigma", 0.0)])
def test_a_bad_setting_is_named(key: str, value: float) -> None:
    with pytest.raises(ValueError, match=rf"rl\.{key}"):
        ESGradients(**{key: value})


def test_cma_maega_es_from_yaml_imitates_and_resumes_bit_for_bit(
    tmp_path: Path, monkeypatch, walker_demos
) -> None:
    """WQDIL's reward and bonus over ES gradients; the reward model learns from the
    perturbation episodes (no walk rollouts), and a resumed run equals the straight one."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("QDIL_PLUGIN_PATH", raising=False)
    es = ["--rl", "qdil.qd.ESGradients", "--rl.init_args.pairs", "3"]
    es += ["--qd.emitter.init_args.es", "cma_es", "--qd.emitter.init_args.ranker", "2imp"]
    es += ["--qd.emitter.init_args.initial_mean", "zero"]
    common = [str(ROOT / "recipes/smoke/walker_il.yaml"), "--demos.path", str(walker_demos), *es]
    main(["fit", *common, "--qd.iterations", "3", "--name", "straight"])
    main(["fit", *common, "--qd.iterations", "2", "--name", "resumed"])
    main(["fit", "--resume", "runs/resumed", "--qd.iterations", "3"])
    straight = rows(Path("runs/straight"))
    assert rows(Path("runs/resumed")) == straight and len(straight) == 3
    for row in straight:
        assert math.isfinite(float(row["rl/jacobian_objective_mean"]))
        assert float(row["rl/walk_step_norm"]) >= 0.0
        assert any(k.startswith("reward/") and row[k] for k in row)  # the model updated
    steps = [float(row["perf/env_steps"]) for row in straight]
    assert steps[0] > 0 and steps == sorted(steps)


def test_an_evaluation_env_too_small_for_the_perturbations_is_named(
    tmp_path: Path, monkeypatch
) -> None:
    monkeypatch.chdir(tmp_path)
    smoke = str(ROOT / "recipes/smoke/walker_true.yaml")
    with pytest.raises(SystemExit, match=r"env\.eval_envs=8: the gradient estimator plays 100"):
        main(["fit", smoke, "--rl", "qdil.qd.ESGradients", "--env.eval_envs", "8"])


def test_the_laptop_es_recipes_parse_with_their_budget() -> None:
    import yaml

    for task in ("walker", "halfcheetah", "humanoid"):
        recipe = yaml.safe_load((ROOT / f"recipes/{task}_cma_maega_es.yaml").read_text())
        assert recipe["rl"]["class_path"] == "qdil.qd.ESGradients"
        assert recipe["qd"]["env_steps"] > 0
