"""Measurement models, one per dataset kind, behind ``MeasurementModel``.

``MODELS`` is the one place that maps a dataset kind to what the toolkit knows about its
instrument; the planner, the simulator and the report ask the class (``model_class``),
never the kind string.
"""

from __future__ import annotations

from ..errors import InputError
from .artifact import ArtifactModel, CrossBarModel
from .base import MeasurementModel
from .sphere_laser import SphereLaserModel
from .tracker import TrackerModel

MODELS: dict[str, type[MeasurementModel]] = {
    "cross_bar": CrossBarModel,
    "artifact_touches": ArtifactModel,
    "sphere_laser": SphereLaserModel,
    "tracker_points": TrackerModel,
}


def model_class(kind: str, *, file=None) -> type[MeasurementModel]:
    """The measurement model class of a dataset ``kind`` (``file``: named in the error)."""
    if kind not in MODELS:
        raise InputError(f"no measurement model for kind {kind!r}; known kinds: "
                         f"{', '.join(MODELS)}", file=file, where="kind")
    return MODELS[kind]


def model_for(dataset, label: str) -> MeasurementModel:
    """The measurement model of ``dataset``'s kind, with placement names under ``label``."""
    return model_class(dataset.kind, file=dataset.path)(dataset, label)


__all__ = ["ArtifactModel", "CrossBarModel", "MODELS", "MeasurementModel", "SphereLaserModel",
           "TrackerModel", "model_class", "model_for"]
