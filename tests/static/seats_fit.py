"""Both implementations of each seat fit it, signatures included: a type checker reads this
file (``basedpyright tests/static/seats_fit.py`` in ``.ci/run``); pytest collects nothing here.

Each function returns its arguments as the seat: a class whose members' signatures differ
from the seat's is an error there, before any run.
"""

from __future__ import annotations

from ribs.schedulers import BanditScheduler
from ribs.schedulers import Scheduler as PyribsScheduler

from qdil.qd import VPPO, ESGradients, EvolutionStrategyEmitter, PPGAEmitter
from qdil.seats import Emitter, GradientEstimator, Scheduler, SearchEmitter, SearchScheduler


def gradient_estimators(vppo: VPPO, es: ESGradients) -> list[GradientEstimator]:
    return [vppo, es]


def emitters(ppga: PPGAEmitter, sep_cma: EvolutionStrategyEmitter) -> list[Emitter]:
    return [ppga, sep_cma]


def search_emitters(ppga: PPGAEmitter) -> list[SearchEmitter]:
    return [ppga]


def schedulers(plain: PyribsScheduler, bandit: BanditScheduler) -> list[Scheduler]:
    return [plain, bandit]


def search_schedulers(plain: PyribsScheduler) -> list[SearchScheduler]:
    return [plain]
