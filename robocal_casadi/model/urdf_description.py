"""A URDF file's serial chain as a robot-file mapping in the ``urdf`` convention.

Walking the chain from the base link to the tip link, fixed joints are composed into the
next moving joint's origin (or, after the last moving joint, into ``flange``), so joint i
of the robot is URDF moving joint i with ``T(i-1,i) = origin_i Motion(axis_i, q_i)``. The
links fixed to a moving link are lumped into it as one point mass at their common centre
of mass (gravity needs no more); links fixed to the base do not move and are left out. A
moving link with no ``<inertial>`` anywhere gets no inertial data for its joint (gravity
effects then use lumped unknowns).

The mapping is what ``robot.robot_from_dict`` reads (lengths [m], angles [rad]), so this
module needs only the transforms, not ``robot``, and ``robot.load_robot`` can read URDF
files.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from .transforms import invert, rpy_from_matrix
from .urdf_document import UrdfDocument, read_document


def is_urdf(path: str | Path) -> bool:
    """True for a ``.urdf`` (or ``.xacro``) file name, or a regular file whose text starts
    with ``<``."""
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


def frame_entry(T: np.ndarray) -> dict:
    """``{xyz, rpy}`` [m, rad] of the pose ``T`` (4x4), the contract's rpy."""
    return {"xyz": [float(v) for v in T[:3, 3]],
            "rpy": [float(v) for v in rpy_from_matrix(T[:3, :3])]}


def chain_description(document: UrdfDocument, *, base_link: str | None = None,
                      tip_link: str | None = None, source: Path | None = None) -> dict:
    """The chain from ``base_link`` to ``tip_link`` (defaults: the root link and the
    single leaf) as a ``urdf``-convention robot-file mapping (module docstring)."""
    base, tip, path = document.chain(base_link, tip_link, source)
    if not any(j.type != "fixed" for j in path):
        raise InputError(f"no moving joint between links {base!r} and {tip!r}",
                         file=source or document.path, where="tip_link")
    pending = np.eye(4)  # fixed joints since the last moving link, in its frame
    bodies: list[list[tuple[float, np.ndarray]]] = []
    moving: list[tuple] = []
    for joint in path:
        mass = document.links.get(joint.child)
        if joint.type == "fixed":
            pending = pending @ joint.origin
            if bodies and mass is not None:
                bodies[-1].append((mass.mass, pending[:3, :3] @ mass.com + pending[:3, 3]))
            continue
        moving.append((joint, pending @ joint.origin))
        pending = np.eye(4)
        bodies.append([] if mass is None else [(mass.mass, mass.com)])
    to_tip = invert(pending)
    joints = []
    for k, ((joint, origin), body) in enumerate(zip(moving, bodies)):
        entry = {"name": joint.name, "child": joint.child, "type": joint.type,
                 **frame_entry(origin), "axis": [float(v) for v in joint.axis]}
        if joint.limits is not None:
            entry["limits"] = [float(v) for v in joint.limits]
        if body:
            total = sum(m for m, _ in body)
            com = np.asarray(sum(m * c for m, c in body) / total if total > 0 else body[0][1],
                             dtype=float)
            if k == len(moving) - 1:  # the last link's com in the tip link's frame
                com = to_tip[:3, :3] @ com + to_tip[:3, 3]
            entry["mass"] = float(total)
            entry["com"] = [float(v) for v in com]
        joints.append(entry)
    return {"name": document.name, "convention": "urdf",
            "units": {"length": "m", "angle": "rad"}, "joints": joints,
            "flange": frame_entry(pending),
            "urdf": {"file": str(document.path.resolve()), "base_link": base, "tip_link": tip}}


def read_description(path: str | Path, *, base_link: str | None = None,
                     tip_link: str | None = None) -> dict:
    """``chain_description`` of the URDF file ``path``."""
    return chain_description(read_document(Path(path)), base_link=base_link, tip_link=tip_link)
