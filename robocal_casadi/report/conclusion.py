"""A short plain-language conclusion, written from the numbers of a calibration.

Each sentence states a figure and what it means: the error before and after on
held-out data (or on the fitting data, saying so), what the effects added, how much of
the model the data could identify, the largest corrections, and warnings when the
numbers call for them (held-out error far above the fit, poor conditioning, a solver
that did not converge).
"""

from __future__ import annotations

from ..calibration.drive_hints import drive_lines
from ..results import HELD_OUT_DECIDE, CalibrationResult
from .accuracy import recommended
from .effect_views import effect_title
from .numbers import ErrorStats, error_noun, format_number, pooled
from .unexplained import remainder_sentence
from .unexplained import sentence as unexplained_sentence

OVERFIT_RATIO = 2.0  # held-out RMS above this multiple of the fit RMS earns a warning
POOR_CONDITION = 1e4  # condition numbers above this earn a warning
CONVERGED_WORDS = ("converged", "success", "ok", "solve_succeeded")


def conclusion_paragraphs(result: CalibrationResult) -> list[str]:
    """The conclusion as a few short paragraphs, the headline first.

    When the model with effects did worse on held-out data than the geometric one (the
    result's ``recommended`` is ``"geometric"``), that comes first.
    """
    held_out = result.validation is not None
    summary = _headline_figures(result)
    paragraphs = _opening(result)
    predicted = _predicted_paragraph(result)
    if predicted:
        paragraphs.append(predicted)
    if not held_out:
        paragraphs.append("No held-out data was given, so this shows how well the model fits, "
                          "not how well it predicts new poses; calibrate with --validate to "
                          "check.")

    if result.effects:
        names = _and([_effect_words(e) for e in result.effects])
        paragraphs.append(f"The geometric calibration alone reached "
                          f"{_length(summary.rms_geometric)} RMS; diagnosis then found "
                          f"{names} in what was left, and adding "
                          f"{'them' if len(result.effects) > 1 else 'it'} brought the error to "
                          f"{_length(summary.rms_final)} (see Effects found).")
    else:
        paragraphs.append(f"The geometric calibration reached {_length(summary.rms_geometric)} RMS;"
                          f" diagnosis found no further effect that the data supports.")
    paragraphs.append(_identifiability_paragraph(result))
    unexplained = unexplained_sentence(result)
    if unexplained:
        paragraphs.append(unexplained)
    left = remainder_sentence(result)
    if left:
        paragraphs.append(left)
    paragraphs += [f"Joint {line[len('joint '):]}." for line in drive_lines(result)]
    warnings = _warnings(result)
    if warnings:
        paragraphs.append("Caution: " + " ".join(warnings))
    return paragraphs


def _length(value_si: float) -> str:
    """A length [m] as the report shows errors and corrections: in mm."""
    return f"{format_number(value_si / 1e-3, 3)} mm"


def _headline_figures(result: CalibrationResult):
    """The RMS figures the conclusion leads with: held-out data over every reading (the
    customer's evidence, gross errors included), else the fit."""
    if result.validation is None:
        return result.fit
    return result.validation_all or result.validation


def _opening(result: CalibrationResult) -> list[str]:
    """The headline (error before and after), preceded by what not to load when the
    effects or the whole calibration should not be used. On held-out data the headline
    covers every reading; the figure without readings set aside as gross errors follows,
    with their count."""
    held_out = result.validation is not None
    summary = _headline_figures(result)
    residuals = result.validation_residuals if held_out else result.residuals
    noun = error_noun(residuals) if residuals else "error"
    aside = result.held_out_set_aside if held_out else 0
    where = ("on the data used for fitting" if not held_out else
             "on every held-out reading" if aside else "on held-out data")
    verb = "fell" if summary.rms_final < summary.rms_nominal else "rose"
    headline = (f"After calibration the {noun} {where} {verb} from {_length(summary.rms_nominal)} "
                f"to {_length(summary.rms_final)} RMS")
    if aside and result.validation is not None:
        headline += (f"; without the {aside} held-out reading{'s' if aside > 1 else ''} set "
                     f"aside as gross errors, from {_length(result.validation.rms_nominal)} to "
                     f"{_length(result.validation.rms_final)}")
    if residuals:
        before = ErrorStats.of(pooled(residuals, "nominal"))
        after = ErrorStats.of(pooled(residuals, "final"))
        kept = " kept" if aside else ""
        headline += (f" (99th percentile from {_length(before.p99)} to {_length(after.p99)}, "
                     f"over {after.count}{kept} measurements)")
    paragraphs = [headline + "."]
    if result.effects and recommended(result) == "geometric":
        worse = ""
        if result.validation is not None:
            worse = (f" ({_length(result.validation.rms_final)} RMS with the effects against "
                     f"{_length(result.validation.rms_geometric)} without)")
        paragraphs.insert(0, f"Use the geometric calibration alone: on held-out data the "
                             f"model with the effects diagnosis found predicts worse than "
                             f"the geometry without them{worse}. robot_calibrated.yaml "
                             f"carries that geometry; do not apply the effects. "
                             f"{HELD_OUT_DECIDE}.")
        paragraphs[1] = paragraphs[1].replace(
            f"to {_length(summary.rms_final)} RMS",
            f"to {_length(summary.rms_final)} RMS with the effects, "
            f"{_length(summary.rms_geometric)} with the geometry alone")
    delivery = getattr(result, "delivery", None)
    if delivery is not None and delivery.refused:
        paragraphs.insert(0, f"Do not load a calibrated model: {delivery.reason}. The robot "
                             f"is better left as it is"
                             + (" with only the mounted instrument calibrated" if
                                delivery.recommended == "instrument_only" else "") + ".")
    return paragraphs


def _predicted_paragraph(result: CalibrationResult) -> str:
    """The predicted accuracy a customer can act on: over the poses the data cover (or the
    declared work cell), the nominal robot's beside it, and the whole box of joint ranges
    with what carries the difference where it differs by more than 2x."""
    predicted = getattr(result, "predicted_accuracy", None)
    delivery = getattr(result, "delivery", None)
    if predicted is None or (delivery is not None and delivery.refused):
        return ""
    text = (f"Predicted tool-position error of robot_calibrated.yaml over "
            f"{predicted.region_words}: {_length(predicted.rms)} RMS")
    if predicted.nominal is not None:
        text += f", against {_length(predicted.nominal.rms)} for the nominal robot there"
    text += "."
    box = predicted.box
    if box is not None and predicted.box_differs:
        text += (f" Over the whole box of joint ranges the data cover (joint combinations "
                 f"the data never visit) it is {_length(box.rms)}")
        if box.nominal is not None:
            text += f" ({_length(box.nominal.rms)} nominal)"
        if predicted.unseen:
            named = _and([f"{u.name} ({_length(u.rms)}; {u.remedy})" for u in predicted.unseen])
            text += f", carried by what these data do not see: {named}"
        else:
            text += ": the data determine the robot only near the measured poses"
        text += ". See Predicted accuracy over the work cell."
    elif predicted.held_out_differs and predicted.unseen and predicted.held_out is not None:
        named = _and([f"{u.name} ({_length(u.rms)}; {u.remedy})" for u in predicted.unseen])
        text += (f" That is more than twice the held-out RMS of the delivered file "
                 f"({_length(predicted.held_out)}): the held-out data measure what the "
                 f"instrument sees, the prediction the whole tool position, and it is carried "
                 f"by the uncertainty these data leave in {named}.")
    return text


def _identifiability_paragraph(result: CalibrationResult) -> str:
    """How much of the model the data identified, and the largest corrections."""
    ident = result.identifiability
    held = len(ident.candidates) - len(ident.identifiable)
    text = (f"{len(ident.identifiable)} of {len(ident.candidates)} candidate parameters were "
            f"identifiable from this data (condition number "
            f"{format_number(ident.condition_number, 3)})")
    text += f"; {held} were held at nominal (see Identifiability)." if held else "."
    changes = _largest_changes(result)
    if changes:
        text += " Largest corrections: " + ", ".join(changes) + "."
    return text


def _warnings(result: CalibrationResult) -> list[str]:
    """Cautions the numbers call for: overfitting, poor conditioning, no convergence."""
    warnings = []
    ident = result.identifiability
    if result.validation is not None and result.fit.rms_final > 0 and \
            result.validation.rms_final > OVERFIT_RATIO * result.fit.rms_final:
        ratio = result.validation.rms_final / result.fit.rms_final
        warnings.append(f"The held-out error is {format_number(ratio, 2)} times the fitting "
                        f"error: the held-out poses may lie outside what the fitting data "
                        f"covered, or the model has absorbed noise; more varied poses would help.")
    if ident.condition_number > POOR_CONDITION:
        warnings.append(f"The identification is poorly conditioned (condition number "
                        f"{format_number(ident.condition_number, 3)}): small measurement errors "
                        f"move some parameters a lot; a planned set of poses would help.")
    status = str(result.solver.get("status", "")).lower()
    if status and not any(word in status for word in CONVERGED_WORDS):
        warnings.append(f"The solver ended with status '{result.solver.get('status')}'; "
                        f"treat the numbers with care.")
    return warnings


def _largest_changes(result: CalibrationResult, per_quantity: int = 2) -> list[str]:
    """The identified lengths and angles that moved most, ``per_quantity`` of each."""
    units = result.units
    moved = []  # lengths in mm, angles in the file's unit
    for quantity in ("length", "angle"):
        entries = [p for p in result.parameters if p.identifiable and p.quantity == quantity]
        entries.sort(key=lambda p: abs(p.estimate - p.nominal), reverse=True)
        scale, unit = units.scale(quantity), units.unit_name(quantity)
        if quantity == "length":
            scale, unit = 1e-3, "mm"
        for p in entries[:per_quantity]:
            change = (p.estimate - p.nominal) / scale
            if change != 0:
                moved.append(f"{p.name} {change:+.3g} {unit}")
    return moved


def _and(items: list[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + f" and {items[-1]}"


def _effect_words(effect) -> str:
    """``joint compliance on joint 2``, ``thermal drift``, in words."""
    text = effect_title(effect.name).lower()
    if effect.joints:
        joints = [str(j) for j in effect.joints]
        text += f" on joint{'s' if len(joints) > 1 else ''} {_and(joints)}"
    return text
