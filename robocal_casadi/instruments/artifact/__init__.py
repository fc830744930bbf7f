"""Probe touches of the sockets of a rigid artifact of certified geometry (``artifact_touches``)."""

from __future__ import annotations

from ..registry import Instrument, Planner
from . import planning, reader, simulator
from .model import ArtifactModel

INSTRUMENT = Instrument(
    kind=ArtifactModel.kind, model=ArtifactModel, blocks=reader.BLOCKS, read=reader.read,
    check=reader.check, simulate=simulator.simulate, corrupt=simulator.corrupt,
    planner=Planner(planning.setup_fields, planning.candidates, planning.refine,
                    planning.feasible),
    noun="plate", turned="touches with the probe held in other orientations",
    plain_posterior=False)

__all__ = ["INSTRUMENT", "ArtifactModel"]
