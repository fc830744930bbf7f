"""What each effect found is plotted against, and the fitted effect to draw over it.

An engineer believes an effect when the error before it (geometric calibration only)
shows a pattern against the effect's own variable and the error after it does not:

- ``torque``: the gravity torque at the joint [N m] (pinocchio's generalized gravity of
  the calibrated robot's links, plus the row's ``payload`` [kg] at ``payload_com`` in
  the flange frame; the flange origin when the data gives none). A robot file without
  link masses has no torque to show: the joint angle instead.
- ``joint``: the joint angle; ``driver``: the angle of the driving joint; ``direction``:
  the joint's direction of motion (-1, 0, +1, from the row order of the full table).
- ``column``: a data column the effect reads (``temperature`` [C], ``time`` [s]).

Which it is, its title and the caption's words come from the effect's class
(``Effect.plot_variable``, ``Effect.plot_values``, ``Effect.title``,
``Effect.view_caption``, ``Effect.view_quantity``, ``Effect.column_label``). The fitted
effect is the effect object's own evaluation (``Effect.contribution``, the same
``delta`` the identification used) with the values of the result
(``result.effect_models``, ``result.effect_values``, SI), on the calibrated geometry:
the joint correction ``dq_j`` [rad or m] for joint effects, the relative length change
``k (T - T_ref)`` [1] for an effect of a data column. Everything returned here
is in display units (``numbers.display_units``: lengths in mm, angles in the robot
file's angle unit; torques in N m, forces in N).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..common.units import Units
from ..effects import EFFECTS, data_columns, effect_title
from ..effects.base import Effect
from ..effects.motion import with_directions
from ..model.robot import Robot
from ..results import CalibrationResult, DatasetResiduals, EffectFinding
from .numbers import display_units, errors_of, joint_reading_unit


@dataclass(frozen=True)
class EffectPanel:
    """One panel: errors before and after against ``x``, with the fitted effect.

    ``x`` and the errors are per measurement (display units); ``fitted`` is the fitted
    effect at each measurement (display units, right-hand axis) or None when it cannot
    be evaluated; ``fitted_is_curve`` says it is a function of ``x`` alone (drawn as a
    line), otherwise it is drawn as points.
    """

    x: np.ndarray
    geometric: np.ndarray
    final: np.ndarray
    x_label: str
    fitted: np.ndarray | None
    fitted_label: str
    fitted_is_curve: bool


@dataclass(frozen=True)
class EffectView:
    """The plot of one effect: its panels, a title and the caption that explains them."""

    name: str
    title: str
    panels: tuple[EffectPanel, ...]
    caption: str
    variable: str  # "torque" | "joint" | "temperature" | "time" | "row"


# ----------------------------------------------------------------------------- fitted models


def effect_models_of(result: CalibrationResult,
                     finding: EffectFinding) -> list[tuple[Effect, np.ndarray]]:
    """``(Effect, theta [SI])`` of every fitted effect model that makes up ``finding``."""
    models = tuple(result.effect_models)
    values = np.asarray(result.effect_values, dtype=float).ravel()
    sizes = [len(m.parameter_names()) for m in models]
    if not models or sum(sizes) != values.size:
        return []
    wanted = set(finding.parameters)
    out, start = [], 0
    for model, size in zip(models, sizes):
        names = set(model.parameter_names())
        if model.name == finding.name and (not wanted or names & wanted):
            out.append((model, values[start:start + size]))
        start += size
    return out


def _numeric_extras(residuals: DatasetResiduals, rows: np.ndarray) -> dict[str, np.ndarray]:
    out = {}
    for name, column in residuals.extras.items():
        try:
            values = np.asarray(column, dtype=float)
        except (TypeError, ValueError):
            continue
        if values.ndim == 1 and len(values) > int(rows.max(initial=-1)):
            out[name] = values[rows]
    return out


def _payload_com(residuals: DatasetResiduals) -> np.ndarray:
    com = getattr(residuals, "payload_com", None)
    return np.zeros(3) if com is None else np.asarray(com, dtype=float).reshape(3)


def joint_corrections(robot: Robot, model, theta: np.ndarray, Q: np.ndarray,
                      extras: dict[str, np.ndarray],
                      payload_com: np.ndarray | None = None) -> np.ndarray:
    """The correction ``dq`` [rad or m] (N x dof) that ``model`` with ``theta`` makes at
    each row of ``Q`` (N x dof readings, SI); ``extras`` maps column names to N values."""
    return model.contribution(robot, theta, Q, extras, payload_com).dq


def gravity_torque_at(robot: Robot, Q: np.ndarray, extras: dict[str, np.ndarray],
                      payload_com: np.ndarray | None = None) -> np.ndarray:
    """Gravity torques [N m] (forces [N] at prismatic joints), N x dof, from pinocchio,
    with the ``payload`` column [kg] (0 without it)."""
    from ..model.pinocchio_model import gravity_torques

    payload = extras.get("payload", 0.0)
    return gravity_torques(robot, Q, payload_mass=payload, payload_com=payload_com)


# ----------------------------------------------------------------------------- views


def _joint_list(joints) -> str:
    joints = list(joints)
    if len(joints) == 1:
        return f"joint {joints[0]}"
    return "joints " + ", ".join(map(str, joints[:-1])) + f" and {joints[-1]}"


def _column_of(finding: EffectFinding, models, residuals) -> str:
    for model, _ in models:
        column = getattr(model, "column", None)
        if column:
            return column
    cls = EFFECTS.get(finding.name)
    named = cls.column_of(tuple(finding.parameters)) if cls is not None else None
    for column in ((named,) if named else ()) + data_columns():
        if any(column in r.extras for r in residuals):
            return column
    return "row"


def effect_view(result: CalibrationResult, finding: EffectFinding) -> EffectView | None:
    """The plot of ``finding`` on the fit data (validation data when there is none).

    None when no error belongs to a data row (nothing to plot against).
    """
    residuals = tuple(r for r in (result.residuals or result.validation_residuals)
                      if (np.asarray(r.rows) >= 0).any())
    if not residuals:
        return None
    units = display_units(result.units)
    models = effect_models_of(result, finding)
    # per-row inputs of the row order (directions of motion) come from the full table
    with_joints = tuple(replace(r, extras=with_directions(r.joints, r.extras,
                                                             result.robot_nominal))
                        for r in residuals if r.joints is not None)
    cls = EFFECTS.get(finding.name)
    joint_effect = (bool(finding.joints) and bool(with_joints)
                    and (cls is None or cls.per != "column"))
    title = effect_title(finding.name)
    if joint_effect:
        title += f", {_joint_list(finding.joints)}"
    if joint_effect:
        return _joint_view(result, finding, title, models, with_joints)
    return _column_view(result, finding, title, models, residuals, units)


def _gather(residuals: DatasetResiduals, units: Units):
    mapped = np.flatnonzero(np.asarray(residuals.rows) >= 0)
    rows = np.asarray(residuals.rows)[mapped].astype(int)
    scale = units.length_scale
    return (rows, errors_of(residuals, "geometric")[mapped] / scale,
            errors_of(residuals, "final")[mapped] / scale)


def _joint_view(result, finding, title, models, residuals) -> EffectView:
    """The view of an effect on joint readings: one panel per joint it acts on."""
    units, robot = display_units(result.units), result.robot_calibrated
    cls = EFFECTS.get(finding.name)
    variable = cls.plot_variable if cls is not None else "joint"
    torque = variable == "torque" and robot.has_inertia
    model = models[0][0] if models else None
    if variable == "torque" or model is None:
        variable = "joint"  # without the effect object, the joint angle is all there is
    panels = []
    fitted_any = False
    for joint in finding.joints:
        j = joint - 1
        angle_scale, angle_unit = joint_reading_unit(robot, j, units)
        xs, geo, fin, fits = [], [], [], []
        for r in residuals:
            rows, g, f = _gather(r, units)
            Q = np.asarray(r.joints, dtype=float)[rows]
            extras = _numeric_extras(r, rows)
            com = _payload_com(r)
            xs.append(_abscissa(robot, model, variable, torque, joint, Q, extras, com, units))
            geo.append(g)
            fin.append(f)
            fits.append(_fitted_dq(robot, models, Q, extras, com, j, angle_scale))
        complete = [v for v in fits if v is not None]
        fitted = np.concatenate(complete) if fits and len(complete) == len(fits) else None
        fitted_any |= fitted is not None
        x_label = _x_label(robot, model, variable, torque, joint, units)
        what = cls.view_quantity if cls is not None else "reading error"
        curve = torque or (cls is not None and cls.view_curve)
        panels.append(EffectPanel(np.concatenate(xs), np.concatenate(geo), np.concatenate(fin),
                                  x_label, fitted, f"fitted {what} dq{joint} [{angle_unit}]",
                                  fitted_is_curve=curve))
    caption = _joint_caption(title, cls, model, variable, torque, fitted_any)
    return EffectView(finding.name, title, tuple(panels), caption,
                      "torque" if torque else "joint")


def _abscissa(robot, model, variable: str, torque: bool, joint: int, Q: np.ndarray,
              extras, com, units: Units) -> np.ndarray:
    """What the panel of ``joint`` (1-based) plots the errors against, one value per row:
    the gravity torque [N m] or force [N], the direction of motion, the driving joint's
    reading or the joint's own reading (display units)."""
    j = joint - 1
    if torque:
        return gravity_torque_at(robot, Q, extras, com)[:, j]
    if variable == "direction" and model is not None:
        return model.plot_values(robot, joint, Q, extras, com)
    if variable == "driver" and model is not None:
        return (model.plot_values(robot, joint, Q, extras, com)
                / joint_reading_unit(robot, _driver(model, joint) - 1, units)[0])
    return Q[:, j] / joint_reading_unit(robot, j, units)[0]


def _x_label(robot, model, variable: str, torque: bool, joint: int, units: Units) -> str:
    """The horizontal axis label of the panel of ``joint`` (1-based), with its unit."""
    j = joint - 1
    if torque:
        unit = "N m" if robot.joints[j].revolute else "N"
        return f"gravity {'torque' if robot.joints[j].revolute else 'force'} " \
               f"at joint {joint} [{unit}]"
    if variable == "direction":
        return f"direction of motion of q{joint} (-1, 0, +1)"
    if variable == "driver":
        driver = _driver(model, joint)
        return f"q{driver} [{joint_reading_unit(robot, driver - 1, units)[1]}]"
    return f"q{joint} [{joint_reading_unit(robot, j, units)[1]}]"


def _joint_caption(title: str, cls, model, variable: str, torque: bool,
                   fitted_any: bool) -> str:
    """The caption of a joint effect's view: what is plotted against what."""
    before_after = ("Error before the effects (geometric calibration only, orange) and after "
                    "them (with every effect found, blue) on the fit data; lines are the RMS "
                    "in bins")
    words = cls.view_caption(torque) if cls is not None else None
    if words is not None:
        against, fitted_text = words
    else:
        against = {"driver": "against the angle of the driving joint",
                   "direction": "against the joint's direction of motion (from the row order)",
                   }.get(variable, "against the joint angle")
        # Without the effect object nothing fitted is drawn (fitted_any is False).
        fitted_text = ("" if model is None else
                       f"the black points (right axis) are the fitted reading error, "
                       f"{model.formula}")
    caption = f"{title}. {before_after}, {against}"
    return caption + (f"; {fitted_text}." if fitted_any else ".")


def _driver(model, joint: int) -> int:
    """The joint driving ``joint`` in a coupling (1-based)."""
    return dict(model.pairs)[joint]


def _fitted_dq(robot, models, Q, extras, com, j, angle_scale) -> np.ndarray | None:
    if not models:
        return None
    total = np.zeros(len(Q))
    for model, theta in models:
        try:
            dq = joint_corrections(robot, model, theta, Q, extras, com)
        except Exception:  # noqa: BLE001 - a missing column etc.: the plot goes without it
            return None
        total += dq[:, j]
    return total / angle_scale


def _column_view(result, finding, title, models, residuals, units) -> EffectView:
    column = _column_of(finding, models, residuals)
    xs, geo, fin, fits = [], [], [], []
    for r in residuals:
        rows, g, f = _gather(r, units)
        if column != "row":
            if column not in r.extras:
                continue
            x = np.asarray(r.extras[column], dtype=float)[rows]
        else:
            x = rows.astype(float)
        xs.append(x)
        geo.append(g)
        fin.append(f)
        reference = next((getattr(m, "reference_value", None) for m, _ in models), None)
        if models and reference is not None and column != "row":
            k = sum(float(theta[0]) for _, theta in models)
            fits.append(k * (x - reference) * 1e6)
        else:
            fits.append(None)
    if not xs:
        return EffectView(finding.name, title, (), f"{title}: no data to plot.", column)
    fitted = None if any(v is None for v in fits) else np.concatenate(fits)
    labels = (cls.column_label(column) for cls in EFFECTS.values())
    label = next((text for text in labels if text), "data row (measurement order)")
    panel = EffectPanel(np.concatenate(xs), np.concatenate(geo), np.concatenate(fin), label,
                        fitted, "fitted length change [µm/m]", True)
    caption = (f"{title}. Error before the effects (geometric calibration only, orange) and "
               f"after them (with every effect found, blue) on the fit data, against "
               f"{label.split(' [')[0]}; lines are the RMS in bins")
    if fitted is not None:
        caption += ("; the dashed line (right axis) is the fitted relative change of every "
                    "link length, k (T - T_ref)")
    return EffectView(finding.name, title, (panel,), caption + ".", column)
