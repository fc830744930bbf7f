"""A URDF file as read: its links, joints and the serial chain between two links.

Only what calibration needs is interpreted (joint origins, axes, types, limits; link
masses and centres of mass); the element tree is kept whole so that a writer can change
joint origins and leave everything else (names, meshes, inertias, limits, comments) as
it was. URDF is SI: lengths [m], angles [rad], masses [kg]. An origin's ``rpy`` means
``R = Rz(yaw) Ry(pitch) Rx(roll)``, the robot file's own convention.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..common.fields import read_text
from ..errors import InputError
from .transforms import pose_from_xyz_rpy

JOINT_TYPES = {"revolute": "revolute", "continuous": "revolute", "prismatic": "prismatic",
               "fixed": "fixed"}
MAX_URDF_BYTES = 16 * 2**20  # a robot description larger than this is refused before reading


@dataclass(frozen=True)
class UrdfElementJoint:
    """One ``<joint>`` of the file: ``type`` revolute, prismatic or fixed (continuous reads
    as revolute without limits), ``origin`` 4x4 [m] in the parent link's frame, unit
    ``axis`` in the joint's frame, ``limits`` [rad or m] or None."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray
    axis: tuple[float, float, float]
    limits: tuple[float, float] | None


@dataclass(frozen=True)
class LinkMass:
    """A link's ``mass`` [kg] and centre of mass ``com`` [m] in the link's frame."""

    mass: float
    com: np.ndarray


class UrdfDocument:
    """A parsed URDF file: ``joints`` by name, ``links`` (name -> ``LinkMass`` or None)."""

    def __init__(self, path: Path, root: ET.Element):
        self.path = path
        self.root = root
        self.name = root.get("name", path.stem)
        self.links: dict[str, LinkMass | None] = {}
        for element in root.findall("link"):
            name = _required(element, "name", path, "a <link>")
            self.links[name] = _link_mass(element, path)
        self.joints: dict[str, UrdfElementJoint] = {}
        self.elements: dict[str, ET.Element] = {}
        for element in root.findall("joint"):
            joint = _joint(element, path, set(self.links))
            if joint.name in self.joints:
                raise InputError(f"joint {joint.name!r} is defined twice", file=path)
            self.joints[joint.name] = joint
            self.elements[joint.name] = element
        self._by_child: dict[str, UrdfElementJoint] = {}
        for joint in self.joints.values():
            if joint.child in self._by_child:
                raise InputError(f"link {joint.child!r} has two parent joints "
                                 f"({self._by_child[joint.child].name!r}, {joint.name!r}): not a "
                                 "tree", file=path)
            self._by_child[joint.child] = joint

    def __repr__(self) -> str:
        return f"UrdfDocument({self.name!r}, {len(self.links)} links, {len(self.joints)} joints)"

    def root_link(self) -> str:
        roots = [name for name in self.links if name not in self._by_child]
        if len(roots) != 1:
            raise InputError(f"expected one root link, found {len(roots)}: "
                             f"{', '.join(roots[:6]) or 'none'}", file=self.path)
        return roots[0]

    def children(self, link: str) -> list[UrdfElementJoint]:
        return [j for j in self.joints.values() if j.parent == link]

    def leaves(self, link: str) -> list[str]:
        """The links without children below ``link`` (``link`` itself when it has none)."""
        out, stack = [], [link]
        while stack:
            current = stack.pop()
            below = self.children(current)
            if not below:
                out.append(current)
            stack.extend(j.child for j in reversed(below))
        return out

    def chain(self, base_link: str | None = None, tip_link: str | None = None,
              source: Path | None = None) -> tuple[str, str, list[UrdfElementJoint]]:
        """``(base_link, tip_link, joints)``: the joints from ``base_link`` (default the
        root link) to ``tip_link`` (default the single leaf below the base), in order.

        A branching tree without a ``tip_link`` is refused with its leaves listed.
        ``source`` names the file that chose the links, in errors.
        """
        where = source or self.path
        base = self.root_link() if base_link is None else base_link
        for key, link in (("base_link", base), ("tip_link", tip_link)):
            if link is not None and link not in self.links:
                raise InputError(f"no link {link!r} in {self.path.name}; links: "
                                 f"{', '.join(list(self.links)[:12])}", file=where, where=key)
        if tip_link is None:
            leaves = self.leaves(base)
            if len(leaves) != 1:
                raise InputError(f"the chain below {base!r} branches into {len(leaves)} leaves "
                                 f"({', '.join(leaves[:12])}): name one as tip_link",
                                 file=where, where="tip_link")
            tip_link = leaves[0]
        joints, link = [], tip_link
        while link != base:
            joint = self._by_child.get(link)
            if joint is None:
                raise InputError(f"link {tip_link!r} is not below link {base!r}", file=where,
                                 where="tip_link")
            joints.append(joint)
            link = joint.parent
        return base, tip_link, joints[::-1]


def read_document(path: str | Path) -> UrdfDocument:
    """Parse a URDF file; a broken one is an ``InputError`` naming the file and line."""
    path = Path(path)
    if path.suffix.lower() == ".xacro":
        raise InputError("a xacro file: expand it to URDF first (xacro FILE > robot.urdf)",
                         file=path)
    text = read_text(path, what="URDF file", limit=MAX_URDF_BYTES)
    try:
        parser = ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))
        root = ET.fromstring(text, parser=parser)
    except ET.ParseError as error:
        line = error.position[0] if error.position else "?"
        raise InputError(f"not well-formed XML ({str(error).split(':')[0]})", file=path,
                         where=f"line {line}") from None
    if root.tag != "robot":
        raise InputError(f"the top element is <{root.tag}>, a URDF file starts with <robot>",
                         file=path)
    return UrdfDocument(path, root)


def _required(element: ET.Element, key: str, path: Path, what: str) -> str:
    value = element.get(key)
    if not value:
        raise InputError(f"{what} without a {key}", file=path)
    return value


def _numbers(text: str | None, count: int, default, path: Path, where: str) -> np.ndarray:
    if text is None:
        if default is None:
            raise InputError(f"expected {count} number(s), found none", file=path, where=where)
        return np.asarray(default, dtype=float)
    try:
        values = np.array([float(v) for v in text.split()], dtype=float)
    except ValueError:
        raise InputError(f"expected {count} numbers, got {text[:60]!r}", file=path,
                         where=where) from None
    if values.shape != (count,) or not np.all(np.isfinite(values)):
        raise InputError(f"expected {count} finite numbers, got {text[:60]!r}", file=path,
                         where=where)
    return values


def origin_of(element: ET.Element | None, path: Path, where: str) -> np.ndarray:
    """The 4x4 pose [m] of an ``<origin xyz rpy>`` element (identity when absent)."""
    if element is None:
        return np.eye(4)
    xyz = _numbers(element.get("xyz"), 3, (0, 0, 0), path, f"{where} origin xyz")
    rpy = _numbers(element.get("rpy"), 3, (0, 0, 0), path, f"{where} origin rpy")
    return pose_from_xyz_rpy(xyz, rpy)


def _joint(element: ET.Element, path: Path, links: set[str]) -> UrdfElementJoint:
    name = _required(element, "name", path, "a <joint>")
    where = f"joint {name!r}"
    kind = element.get("type", "")
    if kind not in JOINT_TYPES:
        raise InputError(f"joint type {kind!r} is not part of a serial chain; expected one of "
                         f"{sorted(JOINT_TYPES)}", file=path, where=where)
    ends = []
    for tag in ("parent", "child"):
        node = element.find(tag)
        link = None if node is None else node.get("link")
        if not link:
            raise InputError(f"no <{tag} link=...>", file=path, where=where)
        if link not in links:
            raise InputError(f"{tag} link {link!r} is not defined", file=path, where=where)
        ends.append(link)
    axis_node = element.find("axis")
    axis = _numbers(None if axis_node is None else axis_node.get("xyz"), 3, (1, 0, 0), path,
                    f"{where} axis")
    norm = float(np.linalg.norm(axis))
    if JOINT_TYPES[kind] != "fixed" and not norm > 1e-9:
        raise InputError("the axis has no direction", file=path, where=f"{where} axis")
    limits = None
    limit = element.find("limit")
    if kind in ("revolute", "prismatic"):
        if limit is None:
            raise InputError(f"a {kind} joint needs <limit lower=... upper=...>", file=path,
                             where=where)
        lo, hi = (float(_numbers(limit.get(k), 1, (0,), path, f"{where} limit {k}")[0])
                  for k in ("lower", "upper"))
        if not lo < hi:
            raise InputError(f"lower limit {lo:g} is not below upper limit {hi:g}", file=path,
                             where=f"{where} limit")
        limits = (lo, hi)
    return UrdfElementJoint(name=name, type=JOINT_TYPES[kind], parent=ends[0], child=ends[1],
                            origin=origin_of(element.find("origin"), path, where),
                            axis=tuple(float(v) for v in axis / (norm or 1.0)),  # type: ignore[arg-type]
                            limits=limits)


def _link_mass(element: ET.Element, path: Path) -> LinkMass | None:
    inertial = element.find("inertial")
    if inertial is None:
        return None
    where = f"link {element.get('name')!r} inertial"
    mass_node = inertial.find("mass")
    if mass_node is None:
        raise InputError("an <inertial> without <mass value=...>", file=path, where=where)
    mass = float(_numbers(mass_node.get("value"), 1, None, path, f"{where} mass")[0])
    if mass < 0:
        raise InputError(f"mass must not be negative, got {mass:g} kg", file=path, where=where)
    return LinkMass(mass, origin_of(inertial.find("origin"), path, where)[:3, 3])
