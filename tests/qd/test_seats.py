"""The QD loop's seats: the recipe takes any class that fills one, names what a class lacks,
and the loop calls nothing of an estimator beyond its seat."""

from __future__ import annotations

from pathlib import Path

import pytest
from ribs.emitters import EvolutionStrategyEmitter
from ribs.schedulers import BanditScheduler
from ribs.schedulers import Scheduler as PyribsScheduler
from run_rows import rows

from qdil.cli import main
from qdil.qd import VPPO, XNES, PPGAEmitter
from qdil.seats import (
    Emitter,
    GradientEstimator,
    Scheduler,
    SearchEmitter,
    SearchScheduler,
    seat_problem,
)
from tests.commands import SMOKE

ROOT = Path(__file__).resolve().parents[2]


class DelegatingEstimator:
    """VPPO behind a class that inherits from nothing and offers its seat's members only."""

    def __init__(
        self,
        rollout_length: int = 128,
        jacobian_iterations: int = 10,
        walk_iterations: int = 10,
        num_minibatches: int = 8,
        update_epochs: int = 4,
    ) -> None:
        self._vppo = VPPO(
            rollout_length=rollout_length,
            jacobian_iterations=jacobian_iterations,
            walk_iterations=walk_iterations,
            num_minibatches=num_minibatches,
            update_epochs=update_epochs,
        )

    def setup(self, *args, **kwargs):
        return self._vppo.setup(*args, **kwargs)

    def compute_jacobian(self, *args, **kwargs):
        return self._vppo.compute_jacobian(*args, **kwargs)

    def walk(self, *args, **kwargs):
        return self._vppo.walk(*args, **kwargs)

    def state_dict(self):
        return self._vppo.state_dict()

    def load_state_dict(self, state):
        self._vppo.load_state_dict(state)


def test_qdils_and_pyribs_classes_fill_the_seats_they_fit() -> None:
    assert issubclass(VPPO, GradientEstimator) and issubclass(DelegatingEstimator, VPPO) is False
    assert issubclass(DelegatingEstimator, GradientEstimator)
    assert issubclass(PPGAEmitter, SearchEmitter) and issubclass(PyribsScheduler, SearchScheduler)
    # a gradient-free pyribs emitter has no search policy to walk; the bandit scheduler keeps
    # its emitters in a pool
    assert SearchEmitter.lacking(EvolutionStrategyEmitter) == [
        "propose",
        "theta",
        "theta_fields",
        "move",
        "coefficient_mean",
    ]
    assert SearchScheduler.lacking(BanditScheduler) == ["emitters"]
    # without an estimator they fit: pyribs' ask/tell is all the loop calls then
    assert issubclass(EvolutionStrategyEmitter, Emitter) and issubclass(PPGAEmitter, Emitter)
    assert issubclass(BanditScheduler, Scheduler) and not issubclass(XNES, Emitter)
    assert seat_problem("qd.scheduler", BanditScheduler) is None
    assert not issubclass(XNES, GradientEstimator)
    assert seat_problem("reward", XNES) is None  # not a seat's key


@pytest.mark.parametrize(
    ("flag", "value", "words"),
    [
        ("--rl", "qdil.qd.XNES", "rl: qdil.qd.xnes.XNES is not a gradient estimator: it lacks "
         "setup, compute_jacobian, walk, state_dict, load_state_dict"),
        ("--qd.emitter", "ribs.emitters.EvolutionStrategyEmitter", "qd.emitter: "
         "ribs.emitters._evolution_strategy_emitter.EvolutionStrategyEmitter is not a search "
         "emitter: it lacks propose, theta, theta_fields, move, coefficient_mean"),
        ("--qd.scheduler", "ribs.schedulers.BanditScheduler", "qd.scheduler: "
         "ribs.schedulers._bandit_scheduler.BanditScheduler is not a search scheduler: it "
         "lacks emitters (a gradient-free one runs with rl: null)"),
        ("--qd.emitter", "qdil.qd.XNES", "qd.emitter: qdil.qd.xnes.XNES is not a search "
         "emitter"),
    ],
)  # fmt: skip
def test_a_class_that_does_not_fill_its_seat_is_refused_naming_what_it_lacks(
    flag: str, value: str, words: str, tmp_path: Path, monkeypatch
) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as refused:
        main(["fit", str(SMOKE), flag, value])
    message = str(refused.value.code)
    assert words in message and "docs/concepts/seats.md" in message, message
    assert not (tmp_path / "runs").exists()


def test_an_estimator_that_only_fills_its_seat_runs_the_loop_as_vppo(
    tmp_path: Path, monkeypatch
) -> None:
    """From YAML, by class path; the loop reaches nothing of it but the seat's members."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("QDIL_PLUGIN_PATH", raising=False)
    common = ["--qd.iterations", "2", "--logging.checkpoint_every", "1"]
    main(["fit", str(SMOKE), *common, "--name", "vppo"])
    main(["fit", "--resume", "runs/vppo", "--qd.iterations", "3"])
    delegating = ["--rl", f"{__name__}.DelegatingEstimator"]
    main(["fit", str(SMOKE), *common, *delegating, "--name", "delegating"])
    main(["fit", "--resume", "runs/delegating", "--qd.iterations", "3"])
    assert rows(Path("runs/delegating")) == rows(Path("runs/vppo"))
    assert len(rows(Path("runs/vppo"))) == 3


def test_a_cvt_search_archive_keeps_its_centroids_resumes_and_is_scored(
    tmp_path: Path, monkeypatch, walker_demos
) -> None:
    """WQDIL's reward with the EBC bonus, which reads the search archive's cells; the
    reported archives stay the grid."""
    import pickle

    import numpy as np
    import torch
    from ribs.archives import CVTArchive, GridArchive

    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("QDIL_PLUGIN_PATH", raising=False)
    il = ROOT / "recipes" / "smoke" / "walker_il.yaml"
    common = [str(il), "--demos.path", str(walker_demos), "--qd.archive.type", "cvt"]
    common += ["--qd.archive.centroids", "30", "--bonus.enabled", "true", "--bonus.type", "ebc"]
    main(["fit", *common, "--qd.iterations", "3", "--name", "straight"])
    main(["fit", *common, "--qd.iterations", "2", "--name", "resumed"])
    main(["fit", "--resume", "runs/resumed", "--qd.iterations", "3"])
    assert rows(Path("runs/resumed")) == rows(Path("runs/straight"))
    state = torch.load("runs/resumed/checkpoints/last.pt", weights_only=False)
    search = pickle.loads(state["scheduler"]).archive
    assert isinstance(search, CVTArchive) and search.centroids.shape == (30, 2)
    np.testing.assert_array_equal(search.centroids, np.load("runs/resumed/centroids.npy"))
    assert isinstance(pickle.loads(state["true_archive"]), GridArchive)
    main(["eval", "runs/resumed", "--episodes", "1"])
    assert (Path("runs/resumed") / "eval.json").is_file()
