"""Residual map: a learned correction of the tool position, where the physics runs out.

When the named effects leave a structured residual, calibration may offer a smooth
correction learned from the data (``calibration.learned``): a world-frame shift of the
measured point as a function of a few joint readings ``x = (q_j1, q_j2, ...)``,

    u_k     = (x_k - lower_k) / (upper_k - lower_k)                       [1]
    f(x)    = sum_i alpha_i exp(-|u - c_i|^2 / (2 l^2))                   [m], world frame
    w(x)    = prod_k s((x_k - lower_k + fade_k) / fade_k)
                     s((upper_k + fade_k - x_k) / fade_k)                 [1]
    s(t)    = 3 t^2 - 2 t^3 for t clipped to [0, 1]
    delta   = gain w(x) f(x)                                              [m]

``c_i`` (centres) are the scaled readings of the rows it was trained on, ``alpha_i``
(3 per centre) the coefficients of the kernel ridge regression, ``l`` the length scale
in scaled units, ``lower``/``upper`` [rad or m] the region the training rows cover and
``fade`` [rad or m] how far beyond it the correction falls to zero (``w`` is 1 inside
the region, 0 beyond the fade, once continuously differentiable). ``gain`` (``map_gain``,
1 as delivered) is the effect's only parameter.

Like link deflection, the shift enters the kinematics on the base's translation
(``base_x``, ``base_y``, ``base_z``), which moves every point of the arm by ``delta``.

The map is *learned*, not physical: it names no cause, holds only inside the region it
was trained on, and is never a candidate of diagnosis nor something the simulator
injects. ``to_entry``/``from_entry`` write and read everything needed to evaluate it
(``effects_calibrated.yaml``).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from ..common.units import Units
from ..errors import InputError
from ..model.robot import Robot
from .base import Effect, Plausible, RowContext
from .checks import column

SHIFT = ("base_x", "base_y", "base_z")
GAIN = "map_gain"
FADE = 0.1  # of each variable's trained span: the margin over which the map falls to zero
KERNEL_BLOCK = 1024  # rows of a kernel matrix whose squared distances are summed at once


def smoothstep(t):
    """``3 t^2 - 2 t^3`` of ``t`` clipped to [0, 1] (numpy or CasADi)."""
    if isinstance(t, (ca.SX, ca.MX, ca.DM)):
        t = ca.fmin(ca.fmax(t, 0.0), 1.0)
    else:
        t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def fade_weight(X: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                fade: np.ndarray) -> np.ndarray:
    """``w`` (N,) at rows ``X`` (N x k) [rad or m] of a region ``lower``..``upper`` with
    margins ``fade`` (each k,) [rad or m]."""
    X = np.atleast_2d(X)
    below = smoothstep((X - lower + fade) / fade)
    above = smoothstep((upper + fade - X) / fade)
    return np.prod(below * above, axis=1)


def squared_distances(U: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Squared distances (N x n) [1] of scaled rows ``U`` (N x k) to ``centres`` (n x k).

    Summed one variable at a time in place, in blocks of rows: no N x n x k temporary (at
    12,000 rows against 800 centres that alone was 230 MB) and none of N x n beside the
    result."""
    U, centres = np.atleast_2d(U), np.atleast_2d(centres)
    out = np.zeros((U.shape[0], centres.shape[0]))
    term = np.empty((min(KERNEL_BLOCK, U.shape[0]), centres.shape[0]))
    for start in range(0, U.shape[0], KERNEL_BLOCK):
        squared = out[start:start + KERNEL_BLOCK]
        part = term[:len(squared)]
        for k in range(U.shape[1]):
            np.subtract(U[start:start + KERNEL_BLOCK, k, None], centres[None, :, k], out=part)
            np.square(part, out=part)
            squared += part
    return out


def kernel_of(squared: np.ndarray, length_scale: float, *, overwrite: bool = False) -> np.ndarray:
    """The Gaussian kernel ``exp(-d^2 / (2 l^2))`` of squared distances ``squared`` [1],
    ``l`` = ``length_scale`` [1]; in ``squared``'s own memory when ``overwrite``."""
    out = squared if overwrite else np.empty_like(squared)
    np.negative(squared, out=out)
    np.divide(out, 2.0 * length_scale ** 2, out=out)
    return np.exp(out, out=out)


def gaussian(U: np.ndarray, centres: np.ndarray, length_scale: float) -> np.ndarray:
    """Kernel matrix (N x n) ``exp(-|u - c|^2 / (2 l^2))`` of scaled rows ``U`` (N x k)
    against ``centres`` (n x k), ``l`` = ``length_scale`` [1]: ``squared_distances`` then
    ``kernel_of`` in place (every entry the same sum in the same order either way)."""
    return kernel_of(squared_distances(U, centres), length_scale, overwrite=True)


class ResidualMap(Effect):
    """A learned world-frame shift of the tool over joint readings ``joints`` (1-based);
    see the module docstring. Arrays are SI; ``centres`` (n x k) scaled, ``coefficients``
    (n x 3) [m]."""

    name = "residual_map"
    title = "Learned residual map"
    unit = "1"
    typical = 1.0
    sentence = "a learned correction of the tool position over {joints} ({values})"
    plot_variable = "joint"
    per = "column"
    tracker_only = True
    simulation_default = ()
    formula = "the tool shifts by a smooth function of the joints, learned from the residual"
    learned: ClassVar[bool] = True

    def __init__(self, joints: tuple[int, ...], centres, coefficients, length_scale: float,
                 lower, upper, fade=None):
        super().__init__(joints)
        self.centres = np.atleast_2d(np.asarray(centres, dtype=float))
        self.coefficients = np.atleast_2d(np.asarray(coefficients, dtype=float))
        self.length_scale = float(length_scale)
        self.lower = np.asarray(lower, dtype=float).reshape(-1)
        self.upper = np.asarray(upper, dtype=float).reshape(-1)
        span = self.upper - self.lower
        self.fade = FADE * span if fade is None else np.asarray(fade, dtype=float).reshape(-1)
        k = len(self.joints)
        if not (self.centres.shape[1] == k and self.coefficients.shape == (len(self.centres), 3)
                and self.lower.shape == self.upper.shape == self.fade.shape == (k,)):
            raise ValueError("ResidualMap: centres (n x k), coefficients (n x 3) and k bounds "
                             "for k joints")
        if not (np.all(span > 0) and np.all(self.fade > 0) and self.length_scale > 0):
            raise ValueError("ResidualMap: needs upper > lower, fade > 0, length_scale > 0")

    def __repr__(self) -> str:
        return (f"ResidualMap(joints={list(self.joints)}, centres={len(self.centres)}, "
                f"length_scale={self.length_scale:.3g})")

    @property
    def label(self) -> str:
        return f"{self.name}[{', '.join(f'q{j}' for j in self.joints)}]"

    def parameter_names(self) -> tuple[str, ...]:
        return (GAIN,)

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        return Plausible(1.0 + 1e-9, basis="a learned map is delivered at the size it was "
                         "fitted with (gain 1)")

    def parameter_joint(self, parameter: str) -> int | None:
        return None

    @classmethod
    def candidates(cls, robot: Robot, extras: Mapping[str, Any]) -> tuple[Effect, ...]:
        """None: the map is learned after diagnosis (``calibration.learned``), not tested."""
        return ()

    # ----------------------------------------------------------------- evaluation

    def weight(self, X: np.ndarray) -> np.ndarray:
        """``w`` at N rows of the map's variables ``X`` (N x k) [rad or m]: 1 inside the
        trained region, 0 beyond its fade."""
        return fade_weight(X, self.lower, self.upper, self.fade)

    def kernel_part(self, X: np.ndarray) -> np.ndarray:
        """``f`` (N x 3) [m] at rows ``X`` (N x k), without the fade."""
        U = (np.atleast_2d(X) - self.lower) / (self.upper - self.lower)
        return gaussian(U, self.centres, self.length_scale) @ self.coefficients

    def shift(self, Q, gain: float = 1.0) -> np.ndarray:
        """The map's shift (N x 3) [m], world frame, at joint readings ``Q`` (N x dof)."""
        X = np.atleast_2d(np.asarray(Q, dtype=float))[:, [j - 1 for j in self.joints]]
        return gain * self.weight(X)[:, None] * self.kernel_part(X)

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, ca.SX]:
        robot = row.robot
        if max(self.joints) > robot.dof:
            raise InputError(f"{self.name}: joint {max(self.joints)} does not exist on "
                             f"{robot.name!r}", where="effects")
        x = ca.vertcat(*[row.q[j - 1] for j in self.joints])
        weight = 1
        squared = ca.SX.zeros(len(self.centres))
        for k in range(len(self.joints)):
            weight = weight * smoothstep((x[k] - self.lower[k] + self.fade[k]) / self.fade[k]) \
                * smoothstep((self.upper[k] + self.fade[k] - x[k]) / self.fade[k])
            u = (x[k] - self.lower[k]) / (self.upper[k] - self.lower[k])
            squared += (u - ca.DM(self.centres[:, k])) ** 2
        kernel = ca.exp(-squared / (2.0 * self.length_scale ** 2))
        shift = theta[0] * weight * ca.mtimes(ca.DM(self.coefficients).T, kernel)
        entries = {row.registry.index(name): shift[c] for c, name in enumerate(SHIFT)}
        return ca.SX.zeros(robot.dof), column(entries, len(row.registry))

    def describe(self, values, units: Units) -> str:
        """Where the map holds, in the file's angle unit (revolute joints assumed)."""
        scale = units.angle_scale
        region = ", ".join(f"q{j} {lo / scale:.3g} .. {hi / scale:.3g} {units.angle}"
                           for j, lo, hi in zip(self.joints, self.lower, self.upper))
        return (f"a learned correction of the tool position over "
                f"{', '.join(f'q{j}' for j in self.joints)} ({len(self.centres)} centres, "
                f"length scale {self.length_scale:.3g} of the trained span), trained on "
                f"{region} and fading to zero outside")

    # ----------------------------------------------------------------- the file

    def to_entry(self) -> dict:
        """What ``effects_calibrated.yaml`` holds besides name, joints and parameters."""
        return {"kind": "learned", "kernel": "gaussian", "length_scale": self.length_scale,
                "region": {f"q{j}": [float(lo), float(hi)]
                           for j, lo, hi in zip(self.joints, self.lower, self.upper)},
                "fade": [float(v) for v in self.fade],
                "centres": [[float(v) for v in c] for c in self.centres],
                "coefficients": [[float(v) for v in c] for c in self.coefficients]}

    def settings(self, columns: Collection[str] = ()) -> dict[str, Any]:
        """The map itself (``to_entry``): what ``from_dict`` rebuilds it from."""
        return self.to_entry()

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any], robot: Robot) -> ResidualMap:
        """The map an effects file's ``entry`` holds (``from_entry``); the robot plays no part."""
        return cls.from_entry(tuple(int(j) for j in entry["joints"]), entry)

    @classmethod
    def from_entry(cls, joints: tuple[int, ...], entry: Mapping[str, Any], path=None,
                   where: str = "effects") -> ResidualMap:
        """The map an effects file's ``entry`` holds; ``InputError`` naming what is wrong."""
        try:
            region = entry["region"]
            lower = [float(region[f"q{j}"][0]) for j in joints]
            upper = [float(region[f"q{j}"][1]) for j in joints]
            built = cls(joints, np.array(entry["centres"], dtype=float),
                        np.array(entry["coefficients"], dtype=float),
                        float(entry["length_scale"]), lower, upper,
                        np.array(entry["fade"], dtype=float))
        except (KeyError, TypeError, ValueError, IndexError) as error:
            raise InputError(f"residual_map: expected region (q<j>: [lower, upper] per joint), "
                             f"fade, length_scale, centres (n x {len(joints)}) and coefficients "
                             f"(n x 3) ({error})", file=path, where=where) from None
        arrays = (built.centres, built.coefficients, built.lower, built.upper, built.fade)
        if not all(np.all(np.isfinite(a)) for a in arrays):
            raise InputError("residual_map: expected finite numbers", file=path, where=where)
        return built
