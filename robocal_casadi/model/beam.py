"""The laser beam direction: one parameterisation for the estimator, the sensor fit and
the planner.

A beam direction is the unit vector ``n = w / |w|`` (flange frame) of a free vector
``w``. Where the direction must move with two unknowns only (the sensor fit's
Levenberg-Marquardt steps, the planner's identification Jacobian), ``w`` is the current
direction ``n0`` moved in its tangent plane::

    w = n0 + E(n0) t,     t = (t1, t2),     E(n0): orthonormal 3 x 2, E^T n0 = 0

so ``dn/dt = E`` at ``t = 0``; there is no pole and no sign choice. The estimator keeps
``w`` itself as three unknowns (``laser_nx, laser_ny, laser_nz``) and fixes its length
with a residual ``|w| - 1``; at ``|w| = 1`` its directions orthogonal to ``n`` are the
same tangent plane.

``beam_direction`` works on numpy arrays and on CasADi symbols; ``tangent_basis`` is
numeric (it picks the cross product by the size of the components).
"""

from __future__ import annotations

import casadi as ca
import numpy as np


def tangent_basis(n) -> np.ndarray:
    """``E`` (3 x 2): orthonormal columns perpendicular to the unit vector ``n``.

    ``e1`` is ``n`` crossed with the coordinate axis least aligned with it, ``e2 = n x e1``.
    """
    x, y, z = (float(v) for v in np.asarray(n, float).ravel())
    if abs(x) <= abs(y) and abs(x) <= abs(z):  # cross with the axis least aligned with n
        e1 = (0.0, z, -y)
    elif abs(y) <= abs(z):
        e1 = (-z, 0.0, x)
    else:
        e1 = (y, -x, 0.0)
    a, b, c = e1
    norm = (a * a + b * b + c * c) ** 0.5
    a, b, c = a / norm, b / norm, c / norm
    return np.array([[a, y * c - z * b], [b, z * a - x * c], [c, x * b - y * a]])


def beam_direction(w, tangent=None, basis: np.ndarray | None = None):
    """The unit beam direction ``n = (w + E t) / |w + E t|`` (flange frame, unitless).

    ``w`` (3,) the free direction vector; ``tangent`` ``t`` (2,), or None for ``t = 0``;
    ``basis`` ``E`` (3 x 2) perpendicular to ``w`` (default ``tangent_basis(w / |w|)``,
    which needs a numeric ``w``). numpy in, numpy out; a CasADi symbol in either
    argument gives a CasADi expression.
    """
    symbolic = isinstance(w, (ca.SX, ca.MX)) or isinstance(tangent, (ca.SX, ca.MX))
    if symbolic and not isinstance(w, (ca.SX, ca.MX)):
        w = ca.DM(np.asarray(w, float).reshape(3, 1))
    if tangent is not None:
        if basis is None:
            numeric = np.asarray(ca.DM(w) if symbolic else w, float).ravel()
            basis = tangent_basis(numeric / np.linalg.norm(numeric))
        w = (w + ca.mtimes(ca.DM(basis), tangent)) if symbolic else (
            np.asarray(w, float).ravel() + basis @ np.asarray(tangent, float).ravel())
    if symbolic:
        return w / ca.norm_2(w)
    w = np.asarray(w, float).ravel()
    return w / np.linalg.norm(w)


__all__ = ["beam_direction", "tangent_basis"]
