"""The quality-diversity side: archives, emitters, xNES, estimators (VPPO, ES), the loop."""

from qdil.qd.emitter import PPGAEmitter
from qdil.qd.es_emitter import EvolutionStrategyEmitter
from qdil.qd.es_gradients import ESGradients
from qdil.qd.vppo import VPPO
from qdil.qd.xnes import XNES

__all__ = ["VPPO", "XNES", "ESGradients", "EvolutionStrategyEmitter", "PPGAEmitter"]
