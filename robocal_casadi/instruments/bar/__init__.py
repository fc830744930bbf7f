"""The cross bar: four sockets at the ends of two equal perpendicular arms (``cross_bar``).

A bar is an artifact: it shares the artifact's degeneracy check and gross errors.
"""

from __future__ import annotations

from ..artifact import reader as artifact_reader
from ..artifact import simulator as artifact_simulator
from ..registry import Instrument
from . import planning, reader, simulator
from .model import CrossBarModel

INSTRUMENT = Instrument(
    kind=CrossBarModel.kind, model=CrossBarModel, blocks=reader.BLOCKS, read=reader.read,
    check=artifact_reader.check, simulate=simulator.simulate, corrupt=artifact_simulator.corrupt,
    plan_setup=planning.setup_fields)

__all__ = ["INSTRUMENT", "CrossBarModel"]
