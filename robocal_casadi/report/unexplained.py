"""What the calibrated model does not explain: a structured residual, in words and a plot.

A result may carry ``unexplained``: None, or ``{rms, unit, share, variables}`` (a
mapping as in result.json, or an object with those attributes): the RMS of a structure
left in the calibrated error, the share of the remaining error it accounts for, and the
variables it follows, strongest first (``q1..qn``, ``direction_q1..direction_qn`` for the
direction of motion of a joint, or an extra column's name). Without a ``unit`` the RMS
is taken as SI [m].
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from ..common.units import LENGTH_SCALE, Units
from ..results import CalibrationResult, DatasetResiduals
from . import kind_figures
from .accuracy import judged_on
from .content import Paragraph, Plot
from .numbers import errors_of, format_number


@dataclass(frozen=True)
class Unexplained:
    """A structured residual: ``rms`` [m], ``share`` [1] of the remaining error, and the
    variables it follows, strongest first."""

    rms: float
    share: float | None
    variables: tuple[str, ...]


def unexplained_of(result: CalibrationResult) -> Unexplained | None:
    """The result's ``unexplained`` entry, read from a mapping or an object; None if absent."""
    raw = getattr(result, "unexplained", None)
    if raw is None:
        return None

    def field(name):
        return raw.get(name) if isinstance(raw, dict) else getattr(raw, name, None)

    rms = field("rms")
    if rms is None:
        return None
    unit = field("unit")
    scale = LENGTH_SCALE.get(unit, 1.0) if isinstance(unit, str) else 1.0
    share = field("share")
    variables = tuple(str(v) for v in (field("variables") or ()))
    return Unexplained(float(rms) * scale, None if share is None else float(share), variables)


def variable_values(residuals: DatasetResiduals, name: str,
                    units: Units) -> tuple[np.ndarray, str] | None:
    """The value of variable ``name`` at each error of ``residuals`` that belongs to a data
    row, with its axis label; None when the dataset does not carry it."""
    rows = np.asarray(residuals.rows)
    mapped = rows[rows >= 0]
    joint, direction = _joint_of(name)
    if joint is not None and residuals.joints is not None and \
            joint < np.asarray(residuals.joints).shape[1]:
        q = np.asarray(residuals.joints, dtype=float)[:, joint]
        if direction:
            motion = np.sign(np.diff(q, prepend=q[0]))
            return motion[mapped], f"direction of motion of q{joint + 1} (-1, 0, +1)"
        return q[mapped] / units.angle_scale, f"q{joint + 1} [{units.angle}]"
    if name in residuals.extras:
        return np.asarray(residuals.extras[name], dtype=float)[mapped], name
    return None


def _joint_of(name: str) -> tuple[int | None, bool]:
    direction = name.startswith("direction_")
    core = name[len("direction_"):] if direction else name
    if core.startswith("q") and core[1:].isdigit() and int(core[1:]) >= 1:
        return int(core[1:]) - 1, direction
    return None, False


def _describe(name: str) -> str:
    joint, direction = _joint_of(name)
    if joint is None:
        return f"the {name} column"
    return f"the direction of motion of joint {joint + 1}" if direction else \
        f"the angle of joint {joint + 1}"


def sentence(result: CalibrationResult) -> str | None:
    """The unexplained structure in one sentence (lengths in mm), or None."""
    found = unexplained_of(result)
    if found is None:
        return None
    share = "" if found.share is None else \
        f", about {100 * found.share:.0f} % of the error that remains"
    follows = f" and follows {_describe(found.variables[0])}" if found.variables else ""
    others = ""
    if len(found.variables) > 1:
        others = " (then " + ", ".join(_describe(v) for v in found.variables[1:3]) + ")"
    return (f"A structure the model does not explain is left in the calibrated error: "
            f"{format_number(found.rms / 1e-3, 3)} mm RMS{share}{follows}{others}. No "
            f"effect in the model accounts for it; see Error before and after.")


def remainder_sentence(result: CalibrationResult) -> str | None:
    """What remains beside the instrument's noise, in one sentence (``Remainder``), or
    None when the result does not carry it."""
    left = getattr(result, "remainder", None)
    if left is None or not hasattr(left, "sentence"):
        return None
    found = unexplained_of(result)
    in_mm = Units("mm", result.units.angle)  # the report shows lengths in mm
    return f"What remains: {left.sentence(in_mm, found.variables if found else ())}."


def unexplained_blocks(result: CalibrationResult, units: Units) -> list:
    """A paragraph and a plot of the calibrated error against the strongest variable,
    and what remains beside the instrument's noise."""
    found = unexplained_of(result)
    left = remainder_sentence(result)
    if found is None:
        return [Paragraph("What remains", "heading"), Paragraph(left)] if left else []
    blocks: list = [Paragraph("What the model does not explain", "heading"),
                    Paragraph(sentence(result) or "")]
    if left:
        blocks.append(Paragraph(left))
    if not found.variables:
        return blocks
    role, residuals = judged_on(result)
    values: list[np.ndarray] = []
    errors: list[np.ndarray] = []
    label = ""
    for r in residuals:
        picked = variable_values(r, found.variables[0], units)
        if picked is None:
            continue
        values.append(picked[0])
        label = picked[1]
        errors.append(errors_of(r, "final")[np.asarray(r.rows) >= 0])
    if values:
        blocks.append(Plot("unexplained", f"{role} data: error magnitude after calibration "
                           f"against {label}, the variable the unexplained structure follows "
                           f"most", partial(kind_figures.residual_against,
                                            np.concatenate(values), np.concatenate(errors),
                                            label, units)))
    return blocks
