"""The instruments: one package per dataset kind behind one registry.

Each kind's package (``tracker/``, ``bar/``, ``artifact/``, ``laser/``) holds its
dataset reader, its measurement model, its simulator and its planning and degeneracy
pieces, and builds one ``Instrument`` record; the lines below register the built-in
kinds, and a new kind adds its own line (``register(...)``) and nothing else.
``instrument(kind)`` is how the rest of the toolkit asks about a kind.
"""

from __future__ import annotations

from . import artifact, bar, laser, tracker
from .dataset import DatasetBase
from .model import MeasurementModel
from .registry import INSTRUMENTS, Instrument, instrument, kinds, register

register(bar.INSTRUMENT)
register(artifact.INSTRUMENT)
register(laser.INSTRUMENT)
register(tracker.INSTRUMENT)


def model_for(dataset, label: str) -> MeasurementModel:
    """The measurement model of ``dataset``'s kind, with placement names under ``label``."""
    return instrument(dataset.kind, file=dataset.path).model(dataset, label)


__all__ = ["INSTRUMENTS", "DatasetBase", "Instrument", "MeasurementModel", "instrument", "kinds",
           "model_for", "register"]
