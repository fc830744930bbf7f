"""URDF: the calibrated chain written over the user's own URDF (``robocal export --urdf``).

Link and joint names, meshes, inertias, limits and comments of the user's file are kept;
only joint origins change (``urdf.writer.urdf_over``). A DH robot is written into that
file's link frames through the nominal robot; without any URDF a DH robot becomes a plain
description (links ``frame_0..frame_n``, joints ``joint_1..joint_n``). Geometry only:
effects have no place in a URDF.
"""

from __future__ import annotations

from .registry import ExportSource, ModelFormat, register


def write(source: ExportSource) -> str:
    """The URDF text of ``source.calibrated`` (module docstring)."""
    if source.urdf is None:
        from ..model.pinocchio_model import urdf_text

        return urdf_text(source.calibrated)
    from ..urdf.writer import urdf_over

    return urdf_over(source.calibrated, source.urdf, nominal=source.nominal,
                     base_link=source.base_link, tip_link=source.tip_link)


FORMAT = ModelFormat(
    name="urdf", flag="--urdf", metavar="OUT.urdf",
    help="write the calibrated chain as URDF",
    expresses="geometry only: every joint origin (xyz, rpy) of the chain",
    write=write)

register(FORMAT)
