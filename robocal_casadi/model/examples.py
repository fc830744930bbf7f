"""Example robots for tests, the simulator, the planner and the demo.

Geometry is typical of each class of arm (values in the style of public data sheets),
built directly in SI; they are fixtures, not vendor models.
"""

from __future__ import annotations

import math

from ..common.units import Units
from .robot import Frame, Joint, Robot

D = math.pi / 180.0


def _limits(lo: float, hi: float) -> tuple[float, float]:
    return (lo * D, hi * D)


def industrial_6r() -> Robot:
    """A 6R industrial arm (offset shoulder, spherical wrist), standard DH, mm/deg file units."""
    rows = [
        # theta, d, a, alpha, limits (deg), mass, com
        (0.0, 0.675, 0.260, -90 * D, _limits(-185, 185), 60.0, (0.0, 0.05, 0.0)),
        (-90 * D, 0.0, 0.680, 0.0, _limits(-140, 80), 40.0, (-0.35, 0.0, 0.10)),
        (0.0, 0.0, -0.035, 90 * D, _limits(-120, 155), 25.0, (0.0, 0.0, 0.05)),
        (0.0, -0.670, 0.0, -90 * D, _limits(-350, 350), 10.0, (0.0, 0.10, 0.0)),
        (0.0, 0.0, 0.0, -90 * D, _limits(-125, 125), 4.0, (0.0, 0.0, 0.02)),
        (0.0, 0.115, 0.0, 0.0, _limits(-350, 350), 1.0, (0.0, 0.0, -0.01)),
    ]
    joints = tuple(Joint("revolute", t, d, a, al, limits=lim, mass=m, com=c)
                   for t, d, a, al, lim, m, c in rows)
    return Robot("industrial-6r", "dh", joints, units=Units("mm", "deg"), has_gravity=True)


def ur_type() -> Robot:
    """A UR-type arm: joints 2, 3, 4 parallel (standard DH, ``beta`` on joints 2 and 3)."""
    rows = [
        (0.0, 0.1273, 0.0, 90 * D, 7.1, (0.021, 0.0, 0.027)),
        (0.0, 0.0, -0.612, 0.0, 12.7, (0.38, 0.0, 0.158)),
        (0.0, 0.0, -0.5723, 0.0, 4.27, (0.24, 0.0, 0.068)),
        (0.0, 0.163941, 0.0, 90 * D, 2.0, (0.0, 0.007, 0.018)),
        (0.0, 0.1157, 0.0, -90 * D, 2.0, (0.0, 0.007, 0.018)),
        (0.0, 0.0922, 0.0, 0.0, 0.365, (0.0, 0.0, -0.026)),
    ]
    joints = tuple(
        Joint("revolute", t, d, a, al, limits=_limits(-360, 360), mass=m, com=c,
              has_beta=i in (1, 2))
        for i, (t, d, a, al, m, c) in enumerate(rows)
    )
    return Robot("ur-type", "dh", joints, units=Units("mm", "deg"))


def panda_7dof() -> Robot:
    """A 7-DOF arm in modified DH (Craig), Panda-like geometry, m/rad file units."""
    h = math.pi / 2
    rows = [
        (0.333, 0.0, 0.0, (-2.8973, 2.8973)),
        (0.0, 0.0, -h, (-1.7628, 1.7628)),
        (0.316, 0.0, h, (-2.8973, 2.8973)),
        (0.0, 0.0825, h, (-3.0718, -0.0698)),
        (0.384, -0.0825, -h, (-2.8973, 2.8973)),
        (0.0, 0.0, h, (-0.0175, 3.7525)),
        (0.0, 0.088, h, (-2.8973, 2.8973)),
    ]
    masses = (4.97, 0.65, 3.23, 3.59, 1.23, 1.67, 0.74)
    coms = ((0.0, -0.03, -0.07), (0.0, -0.07, 0.03), (0.04, 0.03, -0.07), (-0.05, 0.1, 0.03),
            (0.0, 0.04, -0.11), (0.05, -0.01, 0.01), (0.01, 0.0, 0.08))
    joints = tuple(Joint("revolute", 0.0, d, a, al, limits=lim, mass=m, com=c)
                   for (d, a, al, lim), m, c in zip(rows, masses, coms))
    return Robot("panda-7dof", "mdh", joints, tool=Frame((0.0, 0.0, 0.107), (0.0, 0.0, 0.0)),
                 units=Units("m", "rad"), has_tool=True)


def prismatic_rrp() -> Robot:
    """A 4-axis arm with a prismatic third joint (SCARA-like, standard DH), mm/deg units."""
    joints = (
        Joint("revolute", 0.0, 0.40, 0.35, 0.0, limits=_limits(-150, 150), mass=8.0,
              com=(-0.17, 0.0, 0.0)),
        Joint("revolute", 0.0, 0.0, 0.30, math.pi, limits=_limits(-145, 145), mass=5.0,
              com=(-0.15, 0.0, 0.0)),
        Joint("prismatic", 0.0, 0.05, 0.0, 0.0, limits=(0.0, 0.30), mass=1.5, com=(0.0, 0.0, 0.1)),
        Joint("revolute", 0.0, 0.08, 0.0, 0.0, limits=_limits(-360, 360), mass=0.5,
              com=(0.0, 0.0, 0.02)),
    )
    return Robot("rrp-scara", "dh", joints, base=Frame((0.1, -0.2, 0.0), (0.0, 0.0, 0.3)),
                 units=Units("mm", "deg"), has_base=True)


ROBOTS = {"industrial_6r": industrial_6r, "ur_type": ur_type, "panda_7dof": panda_7dof,
          "prismatic_rrp": prismatic_rrp}
