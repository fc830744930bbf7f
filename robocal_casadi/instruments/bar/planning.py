"""What the planner needs of a cross-bar set-up: the artifact's, each socket touched once."""

from __future__ import annotations

from typing import Any

from ..artifact.planning import setup_fields as artifact_fields
from ..artifact.reader import ArtifactTouches


def setup_fields(dataset: ArtifactTouches, options: Any) -> dict:
    """The plan set-up's fields of a cross-bar dataset (``planning.setup``)."""
    return artifact_fields(dataset, options, bar=True, size_key="bar.length")
