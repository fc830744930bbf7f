"""A point laser on the flange measuring a sphere of known radius (``sphere_laser``)."""

from __future__ import annotations

from ..registry import Instrument
from . import planning, reader, simulator
from .model import SphereLaserModel, laser_of

INSTRUMENT = Instrument(
    kind=SphereLaserModel.kind, model=SphereLaserModel, blocks=reader.BLOCKS, read=reader.read,
    simulate=simulator.simulate, corrupt=simulator.corrupt,
    plan_setup=planning.setup_fields)

__all__ = ["INSTRUMENT", "SphereLaserModel", "laser_of"]
