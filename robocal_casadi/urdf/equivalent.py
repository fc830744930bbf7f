"""The standard DH robot equivalent to a URDF chain.

The joint axes, taken as lines in the world at zero readings, fix the DH frames: frame
i-1's z axis is joint i's axis (in the URDF's direction, so readings keep their sign);
frame i's x axis is the common normal from axis i to axis i+1 and its origin where that
normal meets axis i+1. Where two consecutive axes intersect, x is along their cross
product; where they are parallel the normal is not unique and the one through the
previous origin is taken (``d_i = 0``): DH is degenerate there, and the joint is marked
for the Hayati ``beta`` (``has_beta``), which calibration then uses. Frame 0's x is frame
1's (``theta_1 = 0``); frame n lies on axis n under the tip link's origin, with frame
n-1's axes. Everything the DH frames cannot hold goes into ``base`` (world to frame 0)
and ``tool`` (frame n to the URDF's tip link), so the equivalent's tool pose is the URDF's
tip pose at every reading. Instruments given in the tip link's frame must be moved by
``tool`` to sit in the equivalent's flange frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..model.robot import Joint, Robot
from ..model.transforms import invert
from .chain import frame_of

PARALLEL = 1e-9  # |z_a x z_b| below which two axes are parallel


@dataclass(frozen=True)
class DhEquivalent:
    """The equivalent standard DH ``robot`` and ``notes`` on where DH is degenerate."""

    robot: Robot
    notes: tuple[str, ...]


def _axes(robot: Robot) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray]:
    """Joint axes at zero readings (points [m], unit directions, world) and the tip pose."""
    from .writer import _urdf_link_frames

    frames = _urdf_link_frames(robot, np.zeros(robot.dof))
    points, directions = [], []
    for frame, joint in zip(frames, robot.joints):
        points.append(frame[:3, 3].copy())
        directions.append(frame[:3, :3] @ np.asarray(joint.axis, dtype=float))
    return points, directions, frames[-1]


def _placed(value: np.ndarray | None) -> np.ndarray:
    """A frame's axis or origin that the construction has set."""
    if value is None:
        raise ValueError("a DH frame was left unplaced")
    return value


def _frame(x: np.ndarray, z: np.ndarray, origin: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, 0], T[:3, 2] = x, z
    T[:3, 1] = np.cross(z, x)
    T[:3, 3] = origin
    return T


def dh_equivalent(robot: Robot) -> DhEquivalent:
    """The standard DH robot with the same kinematics as the ``urdf`` robot (module
    docstring); joint limits and names of types kept, inertial data left out."""
    if robot.convention != "urdf":
        raise InputError(f"expected a robot read from a URDF file, got convention "
                         f"{robot.convention!r}")
    points, z, tip = _axes(robot)
    n = robot.dof
    notes: list[str] = []
    origins: list[np.ndarray | None] = [None] * n
    xs: list[np.ndarray | None] = [None] * n
    parallel = [False] * n
    # frame i (1..n-1): on axis i+1, x along the normal from axis i
    for i in range(1, n):
        za, zb, pa, pb = z[i - 1], z[i], points[i - 1], points[i]
        cross = np.cross(za, zb)
        if np.linalg.norm(cross) < PARALLEL:
            parallel[i - 1] = True  # row i's beta tilts axis i+1 against axis i
            previous = origins[i - 1] if i > 1 else pa
            origins[i], xs[i] = _parallel_frame(za, zb, pb, _placed(previous), xs[i - 1])
            notes.append(f"axes {i} and {i + 1} are parallel: DH is degenerate there; "
                         f"joint {i} carries the Hayati beta")
        else:
            origins[i], xs[i] = _normal_frame(za, zb, pa, pb, cross)
    # frame 0 on axis 1 with frame 1's x; frame n on axis n under the tip, frame n-1's x
    placed_x = [_placed(v) for v in xs[1:]]  # frames 1..n-1, every one set above
    placed_origin = [_placed(v) for v in origins[1:]]
    x1 = placed_x[0] if n > 1 else _any_normal(z[0])
    origin_0 = (placed_origin[0] - np.dot(placed_origin[0] - points[0], z[0]) * z[0] if n > 1
                else points[0])
    frames = [_frame(x1, z[0], origin_0)]
    frames += [_frame(placed_x[i - 1], z[i], placed_origin[i - 1]) for i in range(1, n)]
    last = frames[-1]
    height = np.dot(tip[:3, 3] - last[:3, 3], last[:3, 2])
    frames.append(_frame(last[:3, 0], last[:3, 2], last[:3, 3] + height * last[:3, 2]))
    joints = _dh_joints(robot, frames, parallel)
    dh = Robot(name=robot.name, convention="dh", joints=joints, base=frame_of(frames[0]),
               tool=frame_of(invert(frames[-1]) @ tip), gravity=robot.gravity,
               has_base=True, has_tool=True, has_gravity=robot.has_gravity,
               transmission=robot.transmission)
    return DhEquivalent(dh, tuple(notes))


def _parallel_frame(za: np.ndarray, zb: np.ndarray, pb: np.ndarray, previous: np.ndarray,
                    previous_x: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Origin [m] and x axis of the frame on axis ``zb`` (through ``pb``) parallel to the
    axis ``za`` before it: the normal through the ``previous`` origin (``d = 0``); on the
    same line, the previous x axis."""
    foot = pb + np.dot(previous - pb, zb) * zb
    offset = foot - previous
    offset -= np.dot(offset, za) * za
    if np.linalg.norm(offset) < 1e-12:  # the same line: keep the previous x
        return foot, previous_x if previous_x is not None else _any_normal(za)
    return foot, offset / np.linalg.norm(offset)


def _normal_frame(za: np.ndarray, zb: np.ndarray, pa: np.ndarray, pb: np.ndarray,
                  cross: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Origin [m] and x axis of the frame on axis ``zb`` (through ``pb``): where the
    common normal from axis ``za`` (through ``pa``) meets it, x along that normal, or along
    ``cross = za x zb`` where the axes intersect."""
    # closest points of the two lines
    w = pa - pb
    b = np.dot(za, zb)
    denominator = 1 - b * b
    s = (b * np.dot(zb, w) - np.dot(za, w)) / denominator
    t = (np.dot(zb, w) - b * np.dot(za, w)) / denominator
    on_a, on_b = pa + s * za, pb + t * zb
    normal = on_b - on_a
    if np.linalg.norm(normal) < 1e-12:
        return on_b, cross / np.linalg.norm(cross)
    return on_b, normal / np.linalg.norm(normal)


def _dh_joints(robot: Robot, frames: list[np.ndarray], parallel: list[bool]
               ) -> tuple[Joint, ...]:
    """The DH rows from frame i-1 to frame i, with the source joints' types and limits."""
    joints = []
    for i, source in enumerate(robot.joints):
        T = invert(frames[i]) @ frames[i + 1]
        theta = float(np.arctan2(T[1, 0], T[0, 0]))
        d = float(T[2, 3])
        a = float(T[0, 3] * np.cos(theta) + T[1, 3] * np.sin(theta))
        alpha = float(np.arctan2(T[2, 1], T[2, 2]))
        joints.append(Joint(source.type, theta, d, a, alpha, limits=source.limits,
                            has_beta=parallel[i], drive=source.drive))
    return tuple(joints)


def _any_normal(z: np.ndarray) -> np.ndarray:
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = helper - np.dot(helper, z) * z
    return x / np.linalg.norm(x)
