"""What the planner's kind pieces share (``planning/``): a candidate and a few helpers.

The planner draws candidates (one reading, or one placement of an artifact with all its
touches) by the kind's ``Planner.candidates``, keeps them runnable while refining by its
``Planner.refine`` and checks a refined one by its ``Planner.feasible``; those live in
each kind's ``planning.py`` and build on what is here. Positions [m], world frame;
joints [rad or m].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..common import exact

MARGIN = 1e-3  # [m] clearance kept above the worktable while refining
ANGLE_MARGIN = 1e-4  # [rad] kept inside the visibility cone and incidence limit


@dataclass(frozen=True)
class Candidate:
    """One bar/artifact placement or one reading.

    ``joints`` (k x dof) the readings of its rows; ``points`` the socket touched by each
    row (touch kinds); ``sockets`` world position [m] of every socket of the placement;
    ``distance`` (k,) [m] the laser reading the nominal robot would give (sphere).
    """

    joints: np.ndarray
    points: tuple[str, ...] = ()
    sockets: dict[str, np.ndarray] = field(default_factory=dict)
    distance: np.ndarray | None = None

    def __repr__(self) -> str:
        extra = f", sockets={sorted(self.sockets)}" if self.sockets else ""
        return f"Candidate(rows={len(self.joints)}{extra})"


def reach_radius(setup) -> float:
    """An upper bound [m] on the distance from joint 1's frame to the instrument point."""
    total = 0.0
    for joint in setup.robot.joints:
        total += abs(joint.a) + abs(joint.d)
        if not joint.revolute and joint.limits is not None:
            total += max(abs(joint.limits[0]), abs(joint.limits[1]))
    return total + exact.norm(setup.offset)


def shoulder(workspace) -> np.ndarray:
    """World position [m] of the joint-1 frame after joint 1 (the reach sphere's centre)."""
    return workspace.kinematics.joint_frames(np.zeros(workspace.dof), workspace.p)[0].full()[:3, 3]


def unit(v: np.ndarray) -> np.ndarray:
    return v / exact.norm(v, axis=-1)[..., None]
