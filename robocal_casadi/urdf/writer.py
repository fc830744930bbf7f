"""A calibrated robot written over the user's own URDF, and as UR's kinematics file.

Only joint origins change: every other element and attribute of the user's file (link and
joint names, meshes, inertias, limits, comments) is written back as it was read.

A ``urdf`` robot (read from a URDF) maps joint by joint: robot joint i's origin holds the
fixed joints between the previous moving link and joint i composed with joint i's own
origin, so joint i's own origin becomes ``P_i^-1 origin_i`` with ``P_i`` those fixed
joints as the file has them; the tip placement after the last moving joint goes into the
first fixed joint that follows it.

A DH or modified-DH robot is first put into the file's link frames. Each DH link splits
into a fixed part before the joint's motion and one after it,
``T(i-1,i) = A_i Jz(q_i) B_i`` (standard DH ``A_i = Rz(theta_i) Tz(d_i)``,
``B_i = Tx(a_i) Rx(alpha_i) Ry(beta_i)``; modified DH ``A_i = Rx(alpha_{i-1}) Tx(a_{i-1})
Rz(theta_i) Tz(d_i)``, ``B_i = Ry(beta_i)``), so ``J_i(q) = base A_1 Jz(q_1) B_1 ... A_i
Jz(q_i)`` is a frame on link i whose z axis is joint i's axis. The file's link i frame
``L_i`` differs from ``J_i`` by a fixed transform ``Y_i = J_i^-1 L_i``, computed once from
the nominal robot (and checked to be the same at other joint readings: the file must
describe the robot the calibration started from, with the file's root link as the robot
file's world frame). The calibrated chain in the file's frames is then
``origin_i = Y_{i-1}^-1 B_{i-1} A_i Y_i`` (``base A_1 Y_1`` for joint 1) and the tip
placement ``Y_n^-1 B_n Y_tip``, exact at every joint reading.
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..model.robot import Robot, UrdfSource
from ..model.transforms import invert, rot_x, rot_y, rot_z, rpy_from_matrix, translation
from ..model.urdf_document import UrdfDocument, read_document
from .chain import frame_of, robot_from_document

AGREEMENT = 1e-6  # [m] and [rad]: a file's link frame must follow the robot file's this closely
UR_SEGMENTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")


def _motion(revolute: bool, q: float) -> np.ndarray:
    return rot_z(q) if revolute else translation(0.0, 0.0, q)


def dh_split(robot: Robot) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(A_i, B_i)`` (4x4, [m]) with ``T(i-1,i) = A_i Jz(q_i) B_i``, everything that
    commutes with the motion placed before it (module docstring)."""
    parts = []
    for joint in robot.joints:
        before = rot_z(joint.theta) @ translation(0.0, 0.0, joint.d)
        if robot.convention == "dh":
            parts.append((before, translation(joint.a, 0.0, 0.0) @ rot_x(joint.alpha)
                          @ rot_y(joint.beta)))
        else:
            parts.append((rot_x(joint.alpha) @ translation(joint.a, 0.0, 0.0) @ before,
                          rot_y(joint.beta)))
    return parts


def _dh_moving_frames(robot: Robot, q) -> list[np.ndarray]:
    """``[J_1(q), ..., J_n(q), J_n(q) B_n]`` world frames [m] (module docstring)."""
    T, out, parts = robot.base.matrix(), [], dh_split(robot)
    for (A, B), joint, reading in zip(parts, robot.joints, q):
        T = T @ A @ _motion(joint.revolute, float(reading))
        out.append(T)
        T = T @ B
    out.append(T)
    return out


def _urdf_link_frames(robot: Robot, q) -> list[np.ndarray]:
    """``[L_1(q), ..., L_n(q), L_tip(q)]`` world frames [m] of a ``urdf`` robot."""
    from ..model.kinematics import axis_motion

    T, out = robot.base.matrix(), []
    for joint, reading in zip(robot.joints, q):
        T = T @ joint.origin.matrix() @ axis_motion(joint.revolute, joint.axis, float(reading))
        out.append(T)
    out.append(T @ robot.flange.matrix())
    return out


def _difference(A: np.ndarray, B: np.ndarray) -> float:
    """Largest of the position difference [m] and the rotation angle [rad] between poses."""
    R = A[:3, :3].T @ B[:3, :3]
    angle = float(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))
    return max(float(np.linalg.norm(A[:3, 3] - B[:3, 3])), angle)


def dh_in_urdf_frames(calibrated: Robot, nominal: Robot, vendor: Robot, *,
                      file: Path | None = None) -> Robot:
    """The calibrated DH robot as ``vendor`` (a ``urdf`` robot of the same arm) with its
    joint origins and flange replaced (module docstring); the fixed transforms come
    from ``nominal``, the robot the calibration started from."""
    vendor_types = [j.type for j in vendor.joints]
    if vendor.dof != nominal.dof or vendor_types != [j.type for j in nominal.joints]:
        raise InputError(f"the URDF chain has joints {[j.type for j in vendor.joints]}, the "
                         f"calibrated robot {[j.type for j in nominal.joints]}", file=file)
    zero = np.zeros(nominal.dof)
    J0, L0 = _dh_moving_frames(nominal, zero), _urdf_link_frames(vendor, zero)
    Y = [invert(J) @ L for J, L in zip(J0, L0)]
    rng = np.random.default_rng(0)
    lower = np.maximum(nominal.lower_limits, -np.pi)
    upper = np.minimum(nominal.upper_limits, np.pi)
    for _ in range(4):
        q = rng.uniform(lower, upper)
        for i, (J, L, fixed) in enumerate(zip(_dh_moving_frames(nominal, q),
                                              _urdf_link_frames(vendor, q), Y)):
            gap = _difference(J @ fixed, L)
            if gap > AGREEMENT:
                link = vendor.joints[i].child if i < vendor.dof else _source(vendor).tip_link
                raise InputError(
                    f"link {link!r} does not follow joint {min(i + 1, nominal.dof)} of the "
                    f"calibrated robot (off by {gap:.3g} m or rad at another joint reading): "
                    "the URDF and the robot file describe different arms, or the robot "
                    "file's world frame is not the URDF's root link", file=file)
    parts = dh_split(calibrated)
    origins = [calibrated.base.matrix() @ parts[0][0] @ Y[0]]
    for i in range(1, calibrated.dof):
        origins.append(invert(Y[i - 1]) @ parts[i - 1][1] @ parts[i][0] @ Y[i])
    flange = invert(Y[-2]) @ parts[-1][1] @ Y[-1]
    joints = tuple(replace(j, origin=frame_of(T)) for j, T in zip(vendor.joints, origins))
    return replace(vendor, joints=joints, flange=frame_of(flange))


def urdf_in_urdf_frames(calibrated: Robot, vendor: Robot, *, file: Path | None = None) -> Robot:
    """A calibrated ``urdf`` robot checked against ``vendor``'s chain (same joint names),
    its base composed into joint 1's origin (the file's root link is the world frame)."""
    names = [j.name for j in calibrated.joints]
    if names != [j.name for j in vendor.joints]:
        raise InputError(f"the URDF chain's joints {[j.name for j in vendor.joints]} are not "
                         f"the calibrated robot's {names}", file=file)
    first = calibrated.joints[0]
    joints = (replace(first, origin=frame_of(calibrated.base.matrix() @ first.origin.matrix())),
              *calibrated.joints[1:])
    return replace(vendor, joints=joints, flange=calibrated.flange)


def own_origins(document: UrdfDocument, chain: Robot) -> dict[str, np.ndarray]:
    """The new ``<origin>`` (4x4, [m]) of each joint of ``document`` that changes, by name,
    so that the file's chain from ``chain.urdf.base_link`` to ``tip_link`` is ``chain``."""
    source = _source(chain)
    _, _, path = document.chain(source.base_link, source.tip_link)
    out, fixed_before, k = {}, np.eye(4), 0
    trailing = []
    for joint in path:
        if joint.type == "fixed":
            if k == chain.dof:
                trailing.append(joint)
            else:
                fixed_before = fixed_before @ joint.origin
            continue
        out[joint.name] = invert(fixed_before) @ chain.joints[k].origin.matrix()
        fixed_before, k = np.eye(4), k + 1
    flange = chain.flange.matrix()
    if trailing:
        rest = np.eye(4)
        for joint in trailing[1:]:
            rest = rest @ joint.origin
        out[trailing[0].name] = flange @ invert(rest)
    elif _difference(flange, np.eye(4)) > 1e-12:
        raise InputError(f"the calibrated tip link sits {_difference(flange, np.eye(4)):.3g} m "
                         f"or rad from the last moving link, and the URDF has no fixed joint "
                         f"after {path[-1].name!r} to hold it", file=document.path)
    return out


def _format(value: float) -> str:
    return repr(0.0 if abs(value) < 1e-300 else float(value))


def set_origins(document: UrdfDocument, origins: dict[str, np.ndarray]) -> None:
    """Write ``origins`` (4x4 by joint name) into the document's ``<origin>`` elements."""
    for name, T in origins.items():
        element = document.elements[name]
        origin = element.find("origin")
        if origin is None:
            origin = ET.SubElement(element, "origin")
        origin.set("xyz", " ".join(_format(v) for v in T[:3, 3]))
        origin.set("rpy", " ".join(_format(v) for v in rpy_from_matrix(T[:3, :3])))


def urdf_over(calibrated: Robot, like: Path, *, nominal: Robot | None = None,
              base_link: str | None = None, tip_link: str | None = None) -> str:
    """The text of ``like`` (a URDF of the same arm) with its joint origins replaced by the
    calibrated chain. A DH robot needs ``nominal`` (module docstring); ``base_link`` and
    ``tip_link`` choose the chain (default: the calibrated robot's own, else root to leaf)."""
    document = read_document(like)
    chain = _chain_over(calibrated, document, like, nominal, base_link, tip_link)
    set_origins(document, own_origins(document, chain))
    body = ET.tostring(document.root, encoding="unicode")
    return '<?xml version="1.0"?>\n' + body + "\n"


def _chain_over(calibrated: Robot, document: UrdfDocument, source: Path,
                nominal: Robot | None, base_link: str | None, tip_link: str | None) -> Robot:
    """The calibrated chain in the link frames of ``document`` (read from ``source``), the
    chain's ends defaulting to the calibrated robot's own. A DH robot needs ``nominal``."""
    if calibrated.urdf is not None:
        base_link = base_link or calibrated.urdf.base_link
        tip_link = tip_link or calibrated.urdf.tip_link
    vendor = robot_from_document(document, base_link=base_link, tip_link=tip_link)
    if calibrated.convention == "urdf":
        return urdf_in_urdf_frames(calibrated, vendor, file=source)
    if nominal is None:
        raise InputError("a DH robot needs its nominal geometry to be written over a URDF",
                         file=source)
    return dh_in_urdf_frames(calibrated, nominal, vendor, file=source)


def dh_ur_origins(robot: Robot) -> list[np.ndarray]:
    """UR's joint origins (4x4, [m]) of a 6-joint DH robot: ``B_{i-1} A_i``, with ``A_1``
    alone for the shoulder (the mounting stays in the description's base frames)."""
    parts = dh_split(robot)
    last = parts[-1][1]
    if _difference(last, np.eye(4)) > 1e-12:
        raise InputError("the calibrated robot's last link has a, alpha or beta after joint 6; "
                         "UR's kinematics file has nowhere to hold them")
    return [parts[0][0]] + [parts[i - 1][1] @ parts[i][0] for i in range(1, 6)]


UR_ANGLE_TOLERANCE = np.radians(2.0)  # [rad]: calibration moves axes by far less, a
#                                       different design by tens of degrees
UR_OFFSET_TOLERANCE = 0.01  # fraction of the reach: how far "intersecting" axes may pass


def joint_axes(robot: Robot, q=None) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(point [m], unit direction)`` of every joint axis in the world frame at ``q``
    [rad or m] (default all zero), from the robot's own geometry."""
    q = np.zeros(robot.dof) if q is None else np.asarray(q, dtype=float)
    if robot.convention == "urdf":
        frames = _urdf_link_frames(robot, q)[:-1]
        return [(T[:3, 3], T[:3, :3] @ np.asarray(j.axis, dtype=float)
                 / np.linalg.norm(j.axis)) for T, j in zip(frames, robot.joints)]
    return [(T[:3, 3], T[:3, 2]) for T in _dh_moving_frames(robot, q)[:-1]]


def _line_distance(first: tuple[np.ndarray, np.ndarray],
                   second: tuple[np.ndarray, np.ndarray]) -> float:
    """Shortest distance [m] between two lines ``(point, unit direction)``."""
    (p, u), (r, v) = first, second
    normal = np.cross(u, v)
    if np.linalg.norm(normal) < 1e-9:  # parallel: distance of r from the first line
        w = r - p
        return float(np.linalg.norm(w - (w @ u) * u))
    return float(abs((r - p) @ normal) / np.linalg.norm(normal))


def ur_structure_problem(robot: Robot) -> str | None:
    """Why ``robot`` does not have a UR arm's structure, or None when it does.

    UR's structure, read from the joint axes at zero joints: six revolute joints; axes 2,
    3 and 4 parallel (shoulder, elbow and wrist 1 turn in one plane) with non-zero upper
    arm and forearm lengths between them; axis 1 perpendicular to axis 2 and meeting it;
    axes 5 and 6 each perpendicular to the one before and meeting it. Angles are judged to
    ``UR_ANGLE_TOLERANCE``, meetings to ``UR_OFFSET_TOLERANCE`` of the reach, so a
    calibrated UR passes and an arm of another design (a spherical wrist, a seventh
    joint, an offset elbow) does not.
    """
    if robot.dof != 6 or not all(j.revolute for j in robot.joints):
        return (f"it has {robot.dof} joints of types {sorted({j.type for j in robot.joints})}, "
                "UR arms have six revolute joints")
    axes = joint_axes(robot)
    reach = max(robot.reach(), 1e-3)
    cos_tol, sin_tol = np.cos(UR_ANGLE_TOLERANCE), np.sin(UR_ANGLE_TOLERANCE)
    for i, j in ((1, 2), (2, 3)):
        if abs(axes[i][1] @ axes[j][1]) < cos_tol:
            return f"axes {i + 1} and {j + 1} are not parallel (UR: shoulder, elbow, wrist 1)"
        if _line_distance(axes[i], axes[j]) <= UR_OFFSET_TOLERANCE * reach:
            return f"axes {i + 1} and {j + 1} have no link length between them"
    for i, j in ((0, 1), (3, 4), (4, 5)):
        if abs(axes[i][1] @ axes[j][1]) > sin_tol:
            return f"axes {i + 1} and {j + 1} are not perpendicular"
        if _line_distance(axes[i], axes[j]) > UR_OFFSET_TOLERANCE * reach:
            return f"axes {i + 1} and {j + 1} do not meet"
    return None


def ur_calibration(calibrated: Robot, like: Path | None = None, *,
                   nominal: Robot | None = None, base_link: str | None = None,
                   tip_link: str | None = None) -> dict:
    """UR's kinematics mapping ``{"kinematics": {shoulder: {x, y, z, roll, pitch, yaw},
    ..., wrist_3: {...}, hash}}`` [m, rad] as ur_description and the UR ROS drivers read
    it: each joint's own origin. From a ``urdf`` robot (or with ``like``, a URDF of the
    arm) the origins are the ones ``urdf_over`` writes; from a DH robot alone they are
    ``B_{i-1} A_i``."""
    problem = ur_structure_problem(calibrated)
    if problem is not None:
        raise InputError(f"robot {calibrated.name!r} is not a UR arm: {problem}; UR's "
                         "kinematics file describes only UR arms", where="--ur-calibration")
    if calibrated.convention == "urdf" or like is not None:
        source = like if like is not None else Path(_source(calibrated).file)
        document = read_document(source)
        chain = _chain_over(calibrated, document, source, nominal, base_link, tip_link)
        changed = own_origins(document, chain)
        origins = [changed[j.name] for j in chain.joints]
    else:
        origins = dh_ur_origins(calibrated)
    block: dict = {}
    for segment, T in zip(UR_SEGMENTS, origins):
        roll, pitch, yaw = (float(v) for v in rpy_from_matrix(T[:3, :3]))
        x, y, z = (float(v) for v in T[:3, 3])
        block[segment] = {"x": x, "y": y, "z": z, "roll": roll, "pitch": pitch, "yaw": yaw}
    digest = hashlib.sha1(repr(sorted((k, sorted(v.items())) for k, v in block.items()))
                          .encode()).hexdigest()[:16]
    block["hash"] = f"calib_robocal_{digest}"
    return {"kinematics": block}


def _source(robot: Robot) -> UrdfSource:
    """Where the ``urdf`` robot ``robot`` came from (a DH robot has no such source)."""
    if robot.urdf is None:
        raise InputError(f"robot {robot.name!r} was not read from a URDF: it names no links")
    return robot.urdf
