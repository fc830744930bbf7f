"""The cross bar: four sockets at the ends of two equal perpendicular arms (``cross_bar``).

A bar is an artifact: it shares the artifact's degeneracy check, gross errors and planning
candidates.
"""

from __future__ import annotations

from ..artifact import planning as artifact_planning
from ..artifact import reader as artifact_reader
from ..artifact import simulator as artifact_simulator
from ..registry import Instrument, Planner
from . import planning, reader, simulator
from .model import CrossBarModel

INSTRUMENT = Instrument(
    kind=CrossBarModel.kind, model=CrossBarModel, blocks=reader.BLOCKS, read=reader.read,
    check=artifact_reader.check, simulate=simulator.simulate, corrupt=artifact_simulator.corrupt,
    planner=Planner(planning.setup_fields, artifact_planning.candidates,
                    artifact_planning.refine, artifact_planning.feasible),
    noun="bar", turned="touches with the probe held in other orientations")

__all__ = ["INSTRUMENT", "CrossBarModel"]
