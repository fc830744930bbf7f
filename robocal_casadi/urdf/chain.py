"""A URDF file's serial chain as a ``Robot`` in the ``urdf`` convention.

Walking the chain from the base link to the tip link, fixed joints are composed into the
next moving joint's origin (or, after the last moving joint, into ``flange``), so joint i
of the robot is URDF moving joint i with ``T(i-1,i) = origin_i Motion(axis_i, q_i)``. The
links fixed to a moving link are lumped into it as one point mass at their common centre
of mass (gravity needs no more); links fixed to the base do not move and are left out. A
link chain where some moving link carries no ``<inertial>`` anywhere gets no inertial data
for that joint (gravity effects then use lumped unknowns).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..robot import Frame, Robot, UrdfJoint, UrdfSource
from ..transforms import invert, rpy_from_matrix
from ..units import SI
from .document import UrdfDocument, read_document


def is_urdf(path: str | Path) -> bool:
    """True for a ``.urdf`` (or ``.xacro``) file name, or a file whose text starts with ``<``."""
    path = Path(path)
    if path.suffix.lower() in (".urdf", ".xacro"):
        return True
    if not path.is_file():  # a pipe or device is never opened here (the reader refuses it)
        return False
    try:
        with path.open("rb") as handle:
            start = handle.read(64).lstrip(b"\xef\xbb\xbf \t\r\n")
    except OSError:
        return False
    return start.startswith(b"<")


def frame_of(T: np.ndarray) -> Frame:
    """``T`` (4x4, [m]) as ``xyz`` [m] and the contract's ``rpy`` [rad]."""
    return Frame(tuple(float(v) for v in T[:3, 3]),  # type: ignore[arg-type]
                 tuple(float(v) for v in rpy_from_matrix(T[:3, :3])))  # type: ignore[arg-type]


def read_urdf_robot(path: str | Path, *, base_link: str | None = None,
                    tip_link: str | None = None, source: Path | None = None) -> Robot:
    """The serial chain of the URDF file ``path`` from ``base_link`` to ``tip_link``
    (defaults: the root link and the single leaf) as a ``urdf`` robot, SI units."""
    path = Path(path)
    return robot_from_document(read_document(path), base_link=base_link, tip_link=tip_link,
                               source=source)


def robot_from_document(document: UrdfDocument, *, base_link: str | None = None,
                        tip_link: str | None = None, source: Path | None = None) -> Robot:
    """See ``read_urdf_robot``."""
    base, tip, path = document.chain(base_link, tip_link, source)
    moving = [j for j in path if j.type != "fixed"]
    if not moving:
        raise InputError(f"no moving joint between links {base!r} and {tip!r}",
                         file=source or document.path, where="tip_link")
    pending = np.eye(4)  # fixed joints since the last moving link, in its frame
    bodies: list[list[tuple[float, np.ndarray]]] = []
    joints: list[dict] = []
    for joint in path:
        mass = document.links.get(joint.child)
        if joint.type == "fixed":
            pending = pending @ joint.origin
            if bodies and mass is not None:
                bodies[-1].append((mass.mass, pending[:3, :3] @ mass.com + pending[:3, 3]))
            continue
        joints.append({"joint": joint, "origin": pending @ joint.origin})
        pending = np.eye(4)
        bodies.append([] if mass is None else [(mass.mass, mass.com)])
    flange = pending
    to_tip = invert(flange)
    out = []
    for k, (entry, body) in enumerate(zip(joints, bodies)):
        joint = entry["joint"]
        mass = com = None
        total = sum(m for m, _ in body)
        if body:
            com_body = (sum(m * c for m, c in body) / total) if total > 0 else body[0][1]
            if k == len(joints) - 1:  # the last link's com in the tip link's frame
                com_body = to_tip[:3, :3] @ com_body + to_tip[:3, 3]
            mass, com = float(total), tuple(float(v) for v in com_body)
        out.append(UrdfJoint(type=joint.type, origin=frame_of(entry["origin"]), axis=joint.axis,
                             limits=joint.limits, mass=mass, com=com,  # type: ignore[arg-type]
                             name=joint.name, child=joint.child))
    return Robot(name=document.name, convention="urdf", joints=tuple(out), units=SI,
                 flange=frame_of(flange),
                 urdf=UrdfSource(str(document.path.resolve()), base, tip))
