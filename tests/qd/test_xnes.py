from __future__ import annotations

import numpy as np
import pytest

from qdil.qd.xnes import XNES, nes_utilities


def test_nes_utilities() -> None:
    u = nes_utilities(10)
    assert abs(u.sum()) < 1e-12
    assert np.all(np.diff(u) <= 0)
    assert u[0] > 0 and u[-1] == -0.1


@pytest.mark.parametrize("dim", [3, 5])
def test_xnes_finds_the_optimum_of_a_shifted_sphere(dim: int) -> None:
    target = np.linspace(-1.5, 2.0, dim)
    es = XNES(sigma0=1.0, solution_dim=dim, seed=0)
    es.reset(np.zeros(dim))
    for _ in range(300):
        x = es.ask()
        fitness = -np.sum((x - target) ** 2, axis=1)
        order = np.argsort(-fitness)
        es.tell(order, fitness[order], num_parents=len(x) // 2)
    np.testing.assert_allclose(es.mean, target, atol=1e-3)
    assert es.sigma < 1e-2


def test_xnes_adapts_its_shape_to_an_elongated_function() -> None:
    es = XNES(sigma0=0.5, solution_dim=2, batch_size=20, seed=1)
    es.reset(np.zeros(2))
    scales = np.array([1.0, 100.0])
    for _ in range(40):  # long enough to adapt, short of float64's floor
        x = es.ask()
        fitness = -np.sum((scales * (x - 1.0)) ** 2, axis=1)
        order = np.argsort(-fitness)
        es.tell(order, fitness[order], num_parents=10)
    cov = es.covariance
    # the Hessian's condition number is 1e4: the covariance follows its inverse
    assert cov[0, 0] > 1000 * cov[1, 1]


def test_defaults_match_evotorch_and_ppga() -> None:
    es = XNES(sigma0=1.0, solution_dim=3, batch_size=300)
    assert es.center_learning_rate == 1.0
    assert es.stdev_learning_rate == pytest.approx(0.6 * (3 + np.log(3)) / (3 * np.sqrt(3)))
    assert es.ask().shape == (300, 3)


def test_errors_and_stop_checks() -> None:
    with pytest.raises(ValueError, match="bounds"):
        XNES(1.0, 3, lower_bounds=-1.0)
    es = XNES(1.0, 3, seed=0)
    with pytest.raises(RuntimeError, match="ask"):
        es.tell(np.arange(3), np.zeros(3), 1)
    assert es.check_stop(np.zeros(7))  # flat ranking
    assert not es.check_stop(np.arange(7.0))
    es.sigma = 1e-13
    assert es.check_stop(np.arange(7.0))
