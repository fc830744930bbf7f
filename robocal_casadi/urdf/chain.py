"""A URDF file's serial chain as a ``Robot`` in the ``urdf`` convention (see
``description`` for how the chain becomes joint origins, a flange and lumped masses)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model.robot import Frame, Robot, robot_from_dict
from ..model.transforms import rpy_from_matrix
from ..model.urdf_description import chain_description, is_urdf
from ..model.urdf_document import UrdfDocument, read_document

__all__ = ["frame_of", "is_urdf", "read_urdf_robot", "robot_from_document"]


def frame_of(T: np.ndarray) -> Frame:
    """``T`` (4x4, [m]) as ``xyz`` [m] and the contract's ``rpy`` [rad]."""
    return Frame(tuple(float(v) for v in T[:3, 3]),  # type: ignore[arg-type]
                 tuple(float(v) for v in rpy_from_matrix(T[:3, :3])))  # type: ignore[arg-type]


def robot_from_document(document: UrdfDocument, *, base_link: str | None = None,
                        tip_link: str | None = None, source: Path | None = None) -> Robot:
    """The chain of ``document`` from ``base_link`` to ``tip_link`` as a ``urdf`` robot."""
    return robot_from_dict(chain_description(document, base_link=base_link, tip_link=tip_link,
                                              source=source), file=document.path)


def read_urdf_robot(path: str | Path, *, base_link: str | None = None,
                    tip_link: str | None = None) -> Robot:
    """The serial chain of the URDF file ``path`` (defaults: the root link to the single
    leaf) as a ``urdf`` robot, SI units."""
    return robot_from_document(read_document(Path(path)), base_link=base_link,
                               tip_link=tip_link)
