"""A point laser on the flange measuring a sphere of known radius (``sphere_laser``)."""

from __future__ import annotations

from ..registry import Instrument, Planner
from . import planning, reader, simulator
from .model import SphereLaserModel, laser_of

INSTRUMENT = Instrument(
    kind=SphereLaserModel.kind, model=SphereLaserModel, blocks=reader.BLOCKS, read=reader.read,
    simulate=simulator.simulate, corrupt=simulator.corrupt,
    planner=Planner(planning.setup_fields, planning.candidates, planning.refine,
                    planning.feasible, scans=True, measured_point=planning.measured_point),
    noun="sphere", turned="scans with the laser tilted to other orientations")

__all__ = ["INSTRUMENT", "SphereLaserModel", "laser_of"]
