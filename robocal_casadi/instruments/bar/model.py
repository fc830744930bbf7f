"""The cross bar (``cross_bar``): an artifact whose four sockets are touched once per pose.

Its residuals are those of ``ArtifactModel`` with distances ``A-C`` and ``B-D`` and one
perpendicularity: exactly the bar residuals ``|AC| - L``, ``|BD| - L``, ``AC.BD / L``.
"""

from __future__ import annotations

from ..artifact.model import ArtifactModel


class CrossBarModel(ArtifactModel):
    """The cross-shaped bar: an artifact whose four sockets are touched once per pose."""

    kind = "cross_bar"
    error_title = "bar error"

    @classmethod
    def table_rows_per_unit(cls, sockets: int, touches: int) -> int:
        return 4  # the four arm ends, touched once per placement
    invisible_reason = ("bar data carry no absolute position: a rigid motion of all touched "
                        "points changes no bar length and no angle")
