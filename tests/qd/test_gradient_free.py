"""The loop without a gradient estimator (``rl: null``): sep-CMA-MAE's emitters and pyribs'
bandit scheduler from YAML, resumed bit for bit, with a learned reward; what does not fit
is refused naming the key."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
import torch
from ribs.archives import GridArchive
from ribs.emitters import EvolutionStrategyEmitter as RibsEvolutionStrategyEmitter
from ribs.schedulers import BanditScheduler
from run_rows import rows

from qdil.cli import main
from qdil.qd import EvolutionStrategyEmitter
from tests.commands import SMOKE

ROOT = Path(__file__).resolve().parents[2]
SEP = [
    "--rl", "null",
    "--qd.emitter", "qdil.qd.EvolutionStrategyEmitter",
    "--qd.emitter.init_args.sigma0", "0.02",
    "--qd.emitter.init_args.es", "sep_cma_es",
    "--qd.emitter.init_args.selection_rule", "mu",
    "--qd.emitter.init_args.batch_size", "4",
    "--qd.emitters", "3",
]  # fmt: skip


def straight_and_resumed(common: list[str]) -> list[dict[str, str]]:
    main(["fit", *common, "--qd.iterations", "3", "--name", "straight"])
    main(["fit", *common, "--qd.iterations", "2", "--name", "resumed"])
    main(["fit", "--resume", "runs/resumed", "--qd.iterations", "3"])
    straight = rows(Path("runs/straight"))
    assert rows(Path("runs/resumed")) == straight and len(straight) == 3
    return straight


def test_sep_cma_mae_imitates_from_yaml_and_resumes_bit_for_bit(
    tmp_path: Path, monkeypatch, walker_demos
) -> None:
    """WQDIL's reward and bonus: the reward model learns from the evaluation episodes."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("QDIL_PLUGIN_PATH", raising=False)
    il = ROOT / "recipes" / "smoke" / "walker_il.yaml"
    straight = straight_and_resumed([str(il), "--demos.path", str(walker_demos), *SEP])
    for row in straight:
        assert any(k.startswith("reward/") and k != "reward/train_per_step" for k in row)
        assert float(row["reward/train_per_step"]) == float(row["reward/train_per_step"])
        assert not any(k.startswith("rl/jacobian") for k in row)  # no estimator ran
    state = torch.load("runs/resumed/checkpoints/last.pt", weights_only=False)
    emitters = pickle.loads(state["scheduler"]).emitters
    assert len(emitters) == 3 and all(isinstance(e, EvolutionStrategyEmitter) for e in emitters)
    assert len({e._opt._rng.bit_generator.state["state"]["state"] for e in emitters}) == 3


def test_a_bandit_scheduler_over_a_pool_of_emitters_runs_and_resumes(
    tmp_path: Path, monkeypatch
) -> None:
    monkeypatch.chdir(tmp_path)
    bandit = ["--qd.scheduler", "ribs.schedulers.BanditScheduler"]
    bandit += ["--qd.scheduler.init_args.num_active", "2"]
    straight = straight_and_resumed([str(SMOKE), *SEP, *bandit])
    steps = [float(row["perf/env_steps"]) for row in straight]
    assert steps == sorted(steps) and steps[0] > 0
    state = torch.load("runs/resumed/checkpoints/last.pt", weights_only=False)
    scheduler = pickle.loads(state["scheduler"])
    assert isinstance(scheduler, BanditScheduler) and len(scheduler.emitter_pool) == 3


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--qd.emitter", "qdil.qd.EvolutionStrategyEmitter",
          "--qd.emitter.init_args.sigma0", "0.1"],
         "qd.emitter: qdil.qd.es_emitter.EvolutionStrategyEmitter is not a search emitter: it "
         "lacks propose, theta, theta_fields, move, coefficient_mean (a gradient-free one runs "
         "with rl: null)"),
        (["--qd.emitters", "2"], "qd.emitters=2: a gradient estimator walks one search emitter"),
        ([*SEP, "--reward", "airl"], "rl: null: the reward model needs log-probs"),
    ],
    ids=["dqd-emitter", "one-search-emitter", "airl"],
)  # fmt: skip
def test_what_does_not_fit_the_run_is_refused_naming_the_key(
    args: list[str], words: str, tmp_path: Path, monkeypatch, walker_demos
) -> None:
    monkeypatch.chdir(tmp_path)
    demos = ["--demos.path", str(walker_demos)] if "airl" in args else []
    with pytest.raises(SystemExit) as refused:
        main(["fit", str(SMOKE), *args, *demos])
    assert words in str(refused.value.code), refused.value.code


def test_the_baseline_recipes_name_the_gradient_free_seats() -> None:
    import yaml

    for task in ("walker", "halfcheetah", "humanoid"):
        for stem in ("sep_cma_mae", "sep_cma_mae_bandit"):
            recipe = yaml.safe_load((ROOT / f"recipes/{task}_{stem}.yaml").read_text())
            assert recipe["rl"] is None and recipe["qd"]["env_steps"] > 0
            assert recipe["qd"]["emitter"]["init_args"]["es"] == "sep_cma_es"


def _archive(threshold_min: float) -> GridArchive:
    return GridArchive(
        solution_dim=4, dims=[5, 5], ranges=[(0, 1)] * 2, learning_rate=0.1,
        threshold_min=threshold_min, seed=1,
    )  # fmt: skip


def _emitters(cls: type, archive: GridArchive, **kwargs) -> object:
    return cls(archive, x0=np.full(4, 0.5), sigma0=0.1, es="sep_cma_es", ranker="imp",
               selection_rule="mu", batch_size=6, seed=3, **kwargs)  # fmt: skip


def test_our_evolution_strategy_emitter_tells_as_pyribs_and_restarts_at_x0_while_empty(
    rng,
) -> None:
    """With elites it is pyribs' emitter, step for step; with none, a restart goes to x0
    where pyribs' samples an elite from the empty archive and fails."""
    ours, theirs = _archive(0.0), _archive(0.0)
    mine = _emitters(EvolutionStrategyEmitter, ours, restart_rule=2)
    pyribs = _emitters(RibsEvolutionStrategyEmitter, theirs, restart_rule=2)
    for _ in range(6):  # restarts every 2 iterations
        solution = mine.ask()
        np.testing.assert_array_equal(solution, pyribs.ask())
        objective, measures = rng.uniform(1, 2, 6), rng.uniform(0, 1, (6, 2))
        mine.tell(solution, objective, measures, ours.add(solution, objective, measures))
        pyribs.tell(solution, objective, measures, theirs.add(solution, objective, measures))
    assert mine.restarts == pyribs.restarts == 3

    ours, theirs = _archive(100.0), _archive(100.0)  # nothing passes the threshold
    mine = _emitters(EvolutionStrategyEmitter, ours, restart_rule="no_improvement")
    pyribs = _emitters(RibsEvolutionStrategyEmitter, theirs, restart_rule="no_improvement")
    solution = mine.ask()
    np.testing.assert_array_equal(solution, pyribs.ask())
    objective, measures = rng.uniform(1, 2, 6), rng.uniform(0, 1, (6, 2))
    with pytest.raises(IndexError):
        pyribs.tell(solution, objective, measures, theirs.add(solution, objective, measures))
    mine.tell(solution, objective, measures, ours.add(solution, objective, measures))
    assert mine.restarts == 1 and ours.empty
    np.testing.assert_array_equal(mine._opt.mean, np.full(4, 0.5))
