"""Measurement models, one per dataset kind, behind ``MeasurementModel``."""

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


def model_for(dataset, label: str) -> MeasurementModel:
    """The measurement model of ``dataset``'s kind, with placement names under ``label``."""
    if dataset.kind not in MODELS:
        raise InputError(f"no measurement model for kind {dataset.kind!r}", file=dataset.path,
                         where="kind")
    return MODELS[dataset.kind](dataset, label)


__all__ = ["ArtifactModel", "CrossBarModel", "MODELS", "MeasurementModel", "SphereLaserModel",
           "TrackerModel", "model_for"]
