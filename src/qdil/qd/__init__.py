"""The quality-diversity side: the seats, archives, the PPGA emitter, xNES, VPPO, the loop."""

from qdil.qd.emitter import PPGAEmitter
from qdil.qd.vppo import VPPO
from qdil.qd.xnes import XNES

__all__ = ["VPPO", "XNES", "PPGAEmitter"]
