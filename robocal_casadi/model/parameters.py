"""Parameters addressed by name.

A ``ParameterRegistry`` maps each parameter name to its index in a CasADi vector and
knows its physical quantity (``length`` [m], ``angle`` [rad] or ``none``), so values
convert to a file's units by name, never by position or substring.

Robot geometry names, joint i counted from 1: ``theta{i}``, ``d{i}``, ``a{i}``,
``alpha{i}``, ``beta{i}``; the base (world to joint-1 frame) ``base_x, base_y, base_z,
base_rx, base_ry, base_rz``; the tool (flange to tool) ``tool_x ... tool_rz``. ``*_rx,
*_ry, *_rz`` are rpy angles ``R = Rz(rz) Ry(ry) Rx(rx)``; see
docs/conventions.md#parameter-names.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError

if TYPE_CHECKING:  # the robot builds its registry from this module: names only, no import
    from .robot import Frame, Robot

JOINT_PARAMETERS = (("theta", "angle"), ("d", "length"), ("a", "length"), ("alpha", "angle"),
                    ("beta", "angle"))
URDF_PARAMETERS = (("x", "length"), ("y", "length"), ("z", "length"), ("roll", "angle"),
                   ("pitch", "angle"), ("yaw", "angle"))
FRAME_PARAMETERS = (("x", "length"), ("y", "length"), ("z", "length"), ("rx", "angle"),
                    ("ry", "angle"), ("rz", "angle"))


@dataclass(frozen=True)
class ParameterRegistry:
    """Ordered parameter names with their quantities; the order is the vector layout."""

    names: tuple[str, ...]
    quantities: tuple[str, ...]

    def __post_init__(self):
        if len(set(self.names)) != len(self.names):
            raise ValueError(f"duplicate parameter names in {self.names}")
        object.__setattr__(self, "_index", {n: i for i, n in enumerate(self.names)})

    def __len__(self) -> int:
        return len(self.names)

    def __contains__(self, name: str) -> bool:
        return name in self._index  # type: ignore[attr-defined]

    def __repr__(self) -> str:
        shown = ", ".join(self.names[:8]) + (", ..." if len(self.names) > 8 else "")
        return f"ParameterRegistry({len(self)} parameters: {shown})"

    def index(self, name: str) -> int:
        """Position of ``name`` in the vector; unknown names list the valid ones."""
        try:
            return self._index[name]  # type: ignore[attr-defined]
        except KeyError:
            raise InputError(
                f"unknown parameter {name!r}; valid names: {', '.join(self.names)}"
            ) from None

    def indices(self, names: Iterable[str]) -> np.ndarray:
        return np.array([self.index(n) for n in names], dtype=int)

    def quantity(self, name: str) -> str:
        return self.quantities[self.index(name)]

    def concat(self, other: ParameterRegistry) -> ParameterRegistry:
        """This registry followed by ``other`` (names must not clash)."""
        return ParameterRegistry(self.names + other.names, self.quantities + other.quantities)

    def subset(self, names: Sequence[str]) -> ParameterRegistry:
        return ParameterRegistry(tuple(names), tuple(self.quantity(n) for n in names))

    # ------------------------------------------------------------------ robot geometry

    @staticmethod
    def for_robot(robot: Robot) -> ParameterRegistry:
        """The geometric parameters of ``robot``: joints, then base, then tool (then the
        flange of a ``urdf`` robot)."""
        names: list[str] = []
        quantities: list[str] = []
        for i in range(1, robot.dof + 1):
            for stem, quantity in joint_parameters(robot):
                names.append(f"{stem}{i}")
                quantities.append(quantity)
        for frame in frames_of(robot):
            for stem, quantity in FRAME_PARAMETERS:
                names.append(f"{frame}_{stem}")
                quantities.append(quantity)
        return ParameterRegistry(tuple(names), tuple(quantities))

    def vector_of(self, robot: Robot) -> np.ndarray:
        """The robot's geometry as a vector in this registry's order [SI]."""
        values = np.zeros(len(self))
        for i, joint in enumerate(robot.joints, start=1):
            if robot.convention == "urdf":
                for k, (stem, _) in enumerate(URDF_PARAMETERS):
                    source = joint.origin.xyz if k < 3 else joint.origin.rpy
                    values[self.index(f"{stem}{i}")] = source[k % 3]
                continue
            for stem, _ in JOINT_PARAMETERS:
                values[self.index(f"{stem}{i}")] = getattr(joint, stem)
        for frame_name in frames_of(robot):
            frame: Frame = getattr(robot, frame_name)
            for k, (stem, _) in enumerate(FRAME_PARAMETERS):
                source = frame.xyz if k < 3 else frame.rpy
                values[self.index(f"{frame_name}_{stem}")] = source[k % 3]
        return values

    def robot_from(self, robot: Robot, values: np.ndarray) -> Robot:
        """A copy of ``robot`` with its geometry replaced by ``values`` [SI]."""
        joints = []
        for i, joint in enumerate(robot.joints, start=1):
            if robot.convention == "urdf":
                v = [float(values[self.index(f"{stem}{i}")]) for stem, _ in URDF_PARAMETERS]
                joints.append(replace(joint, origin=replace(joint.origin, xyz=tuple(v[:3]),
                                                            rpy=tuple(v[3:]))))
                continue
            changes = {stem: float(values[self.index(f"{stem}{i}")])
                       for stem, _ in JOINT_PARAMETERS}
            joints.append(replace(joint, **changes))
        frames = {}
        for frame_name in frames_of(robot):
            v = [float(values[self.index(f"{frame_name}_{stem}")]) for stem, _ in FRAME_PARAMETERS]
            frames[frame_name] = replace(getattr(robot, frame_name), xyz=tuple(v[:3]),
                                         rpy=tuple(v[3:]))
        return replace(robot, joints=tuple(joints), **frames)


def joint_parameters(robot: Robot) -> tuple[tuple[str, str], ...]:
    """``(stem, quantity)`` of each joint's geometric parameters in ``robot``'s convention."""
    return URDF_PARAMETERS if robot.convention == "urdf" else JOINT_PARAMETERS


def frames_of(robot: Robot) -> tuple[str, ...]:
    """The fixed frames whose placements are parameters: base and tool, and the flange of
    a ``urdf`` robot."""
    return ("base", "tool", "flange") if robot.convention == "urdf" else ("base", "tool")


def perturbed_stems(robot: Robot, joint) -> tuple[str, ...]:
    """The stems a random geometric error perturbs on ``joint``: ``theta, d, a, alpha``
    (and ``beta`` where the file gives one) in DH, the six origin numbers in URDF."""
    if robot.convention == "urdf":
        return tuple(stem for stem, _ in URDF_PARAMETERS)
    return ("theta", "d", "a", "alpha") + (("beta",) if joint.has_beta else ())


def length_names(robot: Robot) -> list[str]:
    """The names of the link lengths [m] of ``robot`` (``d{i}, a{i}`` in DH; ``x{i}, y{i},
    z{i}`` in URDF): what a uniform thermal expansion scales."""
    stems = ("x", "y", "z") if robot.convention == "urdf" else ("d", "a")
    return [f"{stem}{i}" for i in range(1, robot.dof + 1) for stem in stems]
