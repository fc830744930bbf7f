"""The measurement models under their earlier import path.

Each model lives with its instrument (``robocal_casadi.instruments.<kind>``) and the
registry there maps a kind to its model; this module only re-exports them.
"""

from __future__ import annotations

from ..instruments import MeasurementModel, instrument, model_for
from ..instruments.artifact import ArtifactModel
from ..instruments.bar import CrossBarModel
from ..instruments.laser import SphereLaserModel
from ..instruments.tracker import TrackerModel


def model_class(kind: str, *, file=None) -> type[MeasurementModel]:
    """The measurement model class of a dataset ``kind`` (``file``: named in the error)."""
    return instrument(kind, file=file).model


__all__ = ["ArtifactModel", "CrossBarModel", "MeasurementModel", "SphereLaserModel",
           "TrackerModel", "model_class", "model_for"]
