"""A laser tracker measuring a reflector on the flange: absolute positions (``tracker_points``)."""

from __future__ import annotations

from ..registry import Instrument, Planner
from . import planning, reader, simulator
from .model import TrackerModel, rigid_registration

INSTRUMENT = Instrument(
    kind=TrackerModel.kind, model=TrackerModel, blocks=reader.BLOCKS, read=reader.read,
    check=reader.check, simulate=simulator.simulate, corrupt=simulator.corrupt,
    planner=Planner(planning.setup_fields, planning.candidates, planning.refine,
                    planning.feasible),
    any_configuration=True,
    noun="tracker",
    turned="another reflector orientation: readings with the flange axis pointing in other "
           "directions")

__all__ = ["INSTRUMENT", "TrackerModel", "rigid_registration"]
