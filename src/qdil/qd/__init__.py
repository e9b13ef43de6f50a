"""The quality-diversity side: archives, the PPGA emitter, xNES, the loop, checkpoints."""

from qdil.qd.emitter import PPGAEmitter
from qdil.qd.xnes import XNES

__all__ = ["XNES", "PPGAEmitter"]
