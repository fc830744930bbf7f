"""Probe touches of the sockets of a rigid artifact of certified geometry (``artifact_touches``)."""

from __future__ import annotations

from ..registry import Instrument
from . import planning, reader, simulator
from .model import ArtifactModel

INSTRUMENT = Instrument(
    kind=ArtifactModel.kind, model=ArtifactModel, blocks=reader.BLOCKS, read=reader.read,
    check=reader.check, simulate=simulator.simulate, corrupt=simulator.corrupt,
    plan_setup=planning.setup_fields)

__all__ = ["INSTRUMENT", "ArtifactModel"]
