"""The report's content, section by section, from a ``CalibrationResult``.

Each ``*_section`` function returns one ``Section`` (or None when it has nothing to
say); ``build_document`` puts them in reading order: conclusion first, then robot and
data, identifiability, parameters, error before and after, effects, sphere and laser,
instrument, and an appendix with the solver's details. Lengths are shown in mm whatever
the file's unit (``numbers.display_units``), angles in the file's angle unit.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from functools import partial

import numpy as np

from ..common.units import Units
from ..effects import is_learned
from ..effects.motion import is_derived_column
from ..instruments import INSTRUMENTS
from ..results import BAND, CalibrationResult, Decision, DiagnosisRecord, mean_square_shares
from . import figures, kind_figures
from .accuracy import accuracy_rows, delivered, judged_on, recommended
from .conclusion import conclusion_paragraphs
from .content import Details, Document, Paragraph, Plot, Section, SignOff, Table
from .effect_views import effect_models_of, effect_title, effect_view
from .info import ReportInfo
from .iso9283 import iso9283_blocks
from .numbers import (
    MODEL_TITLES,
    ErrorStats,
    dataset_name,
    display_units,
    error_noun,
    errors_of,
    format_fixed,
    format_number,
    parameter_decimals,
    pooled,
    quantity_of_placement,
    relation_in_units,
    row_count,
)
from .rejected import rejected_section
from .unexplained import unexplained_blocks

SOLVER_TITLES = {"seconds": "time [s]", "residuals": "residual entries",
                 "free_unknowns": "free unknowns"}
CONVENTION_TITLES = {"dh": "standard Denavit-Hartenberg (dh)",
                     "mdh": "modified Denavit-Hartenberg, Craig (mdh)"}


def build_document(result: CalibrationResult, title: str | None = None,
                   info: ReportInfo | None = None) -> Document:
    """The whole report of ``result`` as a ``Document``; ``info`` the customer's fields."""
    info = info or ReportInfo()
    robot = result.robot_nominal
    title = title or f"Calibration report: {robot.name}"
    convention = CONVENTION_TITLES.get(robot.convention, robot.convention)
    subtitle = (f"{robot.dof}-axis robot, {convention}; data: {', '.join(result.datasets)}")
    shown = display_units(result.units)
    file_units = f"length {result.units.length}, angle {result.units.angle}"
    units_note = (f"Lengths in this report are in {shown.length} and angles in {shown.angle}; "
                  f"the robot file is in {file_units}"
                  + (", as are result.json and robot_calibrated.yaml." if
                     result.units.length != shown.length else "."))
    candidates = (conclusion_section(result), accuracy_section(result),
                  applying_section(result), work_cell_section(result),
                  robot_and_data_section(result), errors_section(result),
                  rejected_section(result), parameters_section(result),
                  effects_section(result),
                  identifiability_section(result), sphere_section(result),
                  instrument_section(result), appendix_section(result))
    facts = info.facts() + (("robot", robot.name),)
    return Document(title, subtitle, tuple(s for s in candidates if s is not None),
                    facts=facts, logo=info.logo_uri(), units_note=units_note,
                    sign_off=sign_off(info))


def sign_off(info: ReportInfo) -> tuple[SignOff, ...]:
    """Who signs the report: whoever measured and calibrated (``operator``) and the
    customer's acceptance (``customer``: the organisation); names not given are left to
    fill in."""
    return (SignOff("Measured and calibrated by", info.operator or ""),
            SignOff("Checked and accepted for the customer", "", info.customer or ""))


# ----------------------------------------------------------------------------- sections


def conclusion_section(result: CalibrationResult) -> Section:
    paragraphs = tuple(Paragraph(text, "conclusion" if i == 0 else "text")
                       for i, text in enumerate(conclusion_paragraphs(result)))
    return Section("conclusion", "Conclusion", paragraphs + (headline_table(result),))


def headline_table(result: CalibrationResult) -> Table:
    """RMS and 99th percentile of the error, nominal / geometric / final, fit and validation."""
    units = display_units(result.units)
    unit = units.length
    rows, muted = [], []
    groups = [("fit", result.fit, result.residuals)]
    if result.validation is not None:
        groups.append(("validation", result.validation, result.validation_residuals))
    for role, summary, residuals in groups:
        values = [summary.rms_nominal, summary.rms_geometric, summary.rms_final]
        p99 = [ErrorStats.of(pooled(residuals, m)).p99 for m in ("nominal", "final")]
        rows.append((role, *(format_number(v / units.length_scale) for v in values),
                     *(format_number(v / units.length_scale) for v in p99)))
        muted.append(False)
    header = ("data", "RMS nominal", "RMS geometric", "RMS final", "99th percentile nominal",
              "99th percentile final")
    return Table("headline", f"Error before and after calibration [{unit}]", header, tuple(rows),
                 tuple(muted), (False,) + (True,) * 5)


def robot_and_data_section(result: CalibrationResult) -> Section:
    robot, calibrated, units = result.robot_nominal, result.robot_calibrated, result.units
    kinds = sorted({j.type for j in robot.joints})
    joint_text = ", ".join(f"{sum(j.type == k for j in robot.joints)} {k}" for k in kinds)
    facts = (
        ("robot", robot.name),
        ("convention", CONVENTION_TITLES.get(robot.convention, robot.convention)),
        ("degrees of freedom", f"{robot.dof} ({joint_text})"),
        ("units of the robot file", f"length {units.length}, angle {units.angle}"),
        ("base frame given", "yes" if robot.has_base else "no"),
        ("tool frame given", "yes" if robot.has_tool else "no"),
        ("calibrated robot", calibrated.name),
    )
    robot_table = Table("robot", "Robot", ("item", "value"), facts)
    rows = []
    for role, residuals in (("fit", result.residuals), ("validation", result.validation_residuals)):
        for r in residuals:
            rows.append((dataset_name(r), role, r.kind, str(row_count(r)),
                         str(len(r.errors_final)), _extra_columns(r.extras)))
    data_table = Table("datasets", "Datasets", ("dataset", "role", "kind", "data rows",
                                                "errors", "extra columns"), tuple(rows),
                       numeric=(False, False, False, True, True, False))
    return Section("robot-data", "Robot and data", (robot_table, data_table))


def appendix_section(result: CalibrationResult) -> Section | None:
    """The solver's details, for the engineer who checks the computation."""
    solver = [(SOLVER_TITLES.get(str(k), str(k).replace("_", " ")),
               format_number(v, 3) if isinstance(v, float) else _scalar_text(v))
              for k, v in result.solver.items() if isinstance(v, (int, float, str, bool))]
    if not solver:
        return None
    return Section("appendix", "Appendix: solver details", (
        Paragraph("How the least-squares problem was solved; these numbers check the "
                  "computation and say nothing about the robot's accuracy.", "note"),
        Table("solver", "Solver", ("item", "value"), tuple(solver))), appendix=True)


def accuracy_section(result: CalibrationResult) -> Section:
    """Mean, RMS, 99th percentile and maximum of the error, before and after (ISO 9283)."""
    units = display_units(result.units)
    noun = error_noun(result.residuals + result.validation_residuals)
    rows, muted = [], []
    same = not result.effects
    for row in accuracy_rows(result):
        if same and row.model == "geometric":
            continue  # equal to final when diagnosis added nothing
        a = row.accuracy
        model = "calibrated" if same and row.model == "final" else MODEL_TITLES[row.model]
        rows.append((row.role, model, str(a.count),
                     *(format_number(v / units.length_scale) for v in (a.mean, a.rms, a.p99,
                                                                       a.max))))
        muted.append(row.model == "nominal")
    table = Table("accuracy", f"Accuracy summary, {noun} [{units.length}]",
                  ("data", "model", "errors", "mean", "RMS", "99th percentile", "maximum"),
                  tuple(rows), tuple(muted), (False, False, True, True, True, True, True))
    text = (f"In the spirit of ISO 9283: statistics of the {noun} magnitude over every "
            f"measurement, for the robot as designed (nominal) and as calibrated. "
            + ("Held-out data were not used in the fit: they show what a customer will see "
               "on new poses." if result.validation is not None else
               "No held-out data were given: these figures show how well the model fits "
               "the data it was fitted on.")) + _validation_frames(result)
    return Section("accuracy", "Accuracy summary", (Paragraph(text), table,
                                                     *iso9283_blocks(result, units)))


def _validation_frames(result: CalibrationResult) -> str:
    """A sentence per kind of instrument placement the held-out data were judged in."""
    held = result.validation_residuals
    fixed = [r for r in held if r.placement_frame.endswith("(fixed)")]
    refitted = [r for r in held if r.placement_frame and r not in fixed]
    text = ""
    if fixed:
        frames = {r.placement_frame for r in fixed}
        text += (f" {_held_out_sets(fixed, ('keeps', 'keep'))} the instrument placement "
                 f"the fit data of the same station gave ({'; '.join(sorted(frames))}): "
                 f"{'their' if len(fixed) > 1 else 'its'} errors are measured in the robot's "
                 f"own frame.")
    if refitted:
        text += (f" {_held_out_sets(refitted, ('has', 'have'))} the instrument placement "
                 f"refitted on {'themselves' if len(refitted) > 1 else 'itself'}: a rigid "
                 f"motion of the robot against the instrument does not show in "
                 f"{'their' if len(refitted) > 1 else 'its'} errors.")
    return text


def _held_out_sets(residuals: list, verb: tuple[str, str]) -> str:
    """``The held-out data set NAME keeps`` or ``The held-out data sets A and B keep``
    (``verb``: singular and plural)."""
    names = [dataset_name(r) for r in residuals]
    if len(names) == 1:
        return f"The held-out data set {names[0]} {verb[0]}"
    listed = ", ".join(names[:-1]) + f" and {names[-1]}"
    return f"The held-out data sets {listed} {verb[1]}"


def _extra_columns(extras) -> str:
    """A dataset's extra columns: the user's, then those derived from the row order
    (direction of motion, travel since it changed), named as derived."""
    given = sorted(c for c in extras if not is_derived_column(c))
    derived = sorted(c for c in extras if is_derived_column(c))
    text = ", ".join(given)
    if derived:
        text += ("; " if text else "") + "derived from the row order: " + ", ".join(derived)
    return text or "-"


def applying_section(result: CalibrationResult) -> Section:
    """What each output file delivers, and how to apply it."""
    units = display_units(result.units)
    role, _ = judged_on(result)
    rows = tuple((d.output, d.contents,
                  *(format_number(v / units.length_scale) for v in (d.accuracy.rms,
                                                                    d.accuracy.p99,
                                                                    d.accuracy.max)))
                 for d in delivered(result))
    table = Table("delivered", f"Accuracy each output delivers, on the {role} data "
                  f"[{units.length}]", ("output", "what it contains", "RMS", "99th percentile",
                                         "maximum"), rows,
                  numeric=(False, False, True, True, True))
    blocks: list = [Paragraph(
        "robot_calibrated.yaml is the robot file with the calibrated geometry, in the units "
        "of the file given; it replaces the nominal model in the controller or in the "
        "offline programming system. It carries no effects: a controller that loads it "
        "alone delivers the geometric calibration's accuracy. result.json lists every "
        "parameter with its standard error and the effects found; an effect improves the "
        "robot only where the controller applies it."), table]
    choice = recommended(result)
    if result.effects and choice == "geometric":
        blocks.append(Paragraph("Use the geometry alone: on held-out data the model with "
                                "effects did worse than the geometric calibration.",
                                "conclusion"))
    return Section("applying", "Applying the result", tuple(blocks))


def work_cell_section(result: CalibrationResult) -> Section | None:
    """The tool-position error predicted for robot_calibrated.yaml away from the measured
    points, over the work cell (``job.accuracy``), beside the nominal robot's over the
    same poses; the whole box of joint ranges beside it where it differs by more than 2x,
    with what carries the difference."""
    predicted = result.predicted_accuracy
    if predicted is None:
        return None
    units = display_units(result.units)
    scale, unit = units.length_scale, units.length
    figures_of = [("calibrated", predicted), ("nominal robot", predicted.nominal)]
    box = predicted.box if predicted.box_differs else None
    if box is not None:
        figures_of += [("calibrated, whole box", box), ("nominal robot, whole box", box.nominal)]
    shown = [(label, f) for label, f in figures_of if f is not None]

    def row(name: str, value) -> tuple[str, ...]:
        return (name, *(format_number(value(f) / scale) if value(f) is not None else "-"
                        for _, f in shown))

    rows: list[tuple[str, ...]] = [row("RMS", lambda f: f.rms),
                                   row("95th percentile", lambda f: f.p95),
                                   row("maximum", lambda f: f.max)]
    rows.append(row("of which the model does not describe",
                    lambda f: getattr(f, "structured", None)))
    if predicted.band is not None:  # where one robot's RMS lies (quantiles over robots)
        for k, label in enumerate((f"RMS of one robot, {100 * BAND[0]:.0f}% of robots below",
                                   f"RMS of one robot, {100 * BAND[1]:.0f}% of robots below")):
            rows.insert(1 + k, row(label, lambda f, k=k: None if getattr(f, "band", None)
                                   is None else f.band[k]))
    text = (f"The measured points say how well the model fits where the robot was measured. "
            f"Away from them, the error of robot_calibrated.yaml is predicted from the "
            f"uncertainty left in every parameter (the data and the tolerances together) and "
            f"from what the model still lacks (including what effects found in the data move "
            f"that the geometry alone does not, under the loads of the data), at "
            f"{predicted.samples} poses: {predicted.region_words}, after the robot's "
            f"placement in the cell (a rigid motion of its base) is registered. The nominal "
            f"robot's error over the same poses is beside it: the calibration's correction "
            f"there plus what remains uncertain. The RMS is an average over robots "
            f"calibrated like this one; one robot's RMS scatters about it, within the stated "
            f"range for {predicted.band_words}.")
    blocks: list = [Paragraph(text)]
    if box is not None:
        blocks.append(Paragraph(_box_words(predicted, scale, unit), "conclusion"))
    elif predicted.held_out_differs and predicted.unseen and predicted.held_out is not None:
        blocks.append(Paragraph(_held_out_words(predicted, scale, unit), "conclusion"))
    header = ("statistic", *(label for label, _ in shown))
    blocks.append(Table("predicted", f"Predicted tool-position error [{unit}]", header,
                        tuple(rows), numeric=(False, *(True for _ in shown))))
    if len(predicted.errors):
        blocks.append(Plot("predicted-error", "Predicted tool-position error of "
                           "robot_calibrated.yaml at the poses of the prediction.",
                           partial(figures.predicted_errors, predicted.errors, scale, unit,
                                   predicted.region_words)))
    return Section("work-cell", "Predicted accuracy over the work cell", tuple(blocks))


def _held_out_words(predicted, scale: float, unit: str) -> str:
    """Why the prediction is more than twice the held-out RMS: what carries it."""
    named = "; ".join(f"{u.name}, {format_number(u.rms / scale)} {unit}: {u.remedy}"
                      for u in predicted.unseen)
    return (f"The prediction is more than twice the held-out RMS of robot_calibrated.yaml "
            f"({format_number(predicted.held_out / scale)} {unit}): the held-out data "
            f"measure what the instrument sees, the prediction the whole tool position. What "
            f"carries it is the uncertainty these data leave in: {named}.")


def _box_words(predicted, scale: float, unit: str) -> str:
    """Why the whole box of joint ranges gives another figure, and what would change it."""
    box = predicted.box
    text = (f"Over the whole box of joint ranges the data cover (every combination of joint "
            f"angles within the measured ranges, including orientations the data never "
            f"visit) the prediction is {format_number(box.rms / scale)} {unit} RMS, "
            f"{format_number(box.rms / predicted.rms, 2)} times the figure over "
            f"{predicted.region_words}.")
    if not predicted.unseen:
        return text + (" The data determine the robot only near the measured poses: "
                       "measure more of the work cell (other poses, another placement of "
                       "the instrument) before sending it elsewhere.")
    named = "; ".join(f"{u.name}, which carries {format_number(u.rms / scale)} {unit} of "
                      f"it: {u.remedy}" for u in predicted.unseen)
    return (text + f" What carries the difference is what these data do not see, so it "
            f"keeps (nearly) the uncertainty of its tolerance: {named}. Declare the work "
            f"cell (work_cell: in the dataset file) where the robot will work only as it "
            f"was measured, or measure so as to see it.")


_RELATION = re.compile(r"(\w+) (acts like|~) ([^);]*)")


def quantity_lookup(result: CalibrationResult) -> Callable[[str], str]:
    """The quantity (length, angle, none) of any unknown a calibration names."""
    registry = result.robot_nominal.parameters()
    mounted = dict(getattr(result, "mounted_quantities", None) or {})

    def quantity_of(name: str) -> str:
        if name in registry.names:
            return registry.quantity(name)
        return mounted.get(name) or quantity_of_placement(name)

    return quantity_of


def relations_in_units(text: str, result: CalibrationResult) -> str:
    """``text`` with every ``NAME acts like ...`` / ``NAME ~ ...`` relation's coefficients
    (SI in the calibration's words) in the report's units."""
    units = display_units(result.units)
    quantity_of = quantity_lookup(result)
    return _RELATION.sub(lambda m: f"{m.group(1)} {m.group(2)} " + relation_in_units(
        m.group(3), m.group(1), quantity_of, units), text)


def identifiability_section(result: CalibrationResult) -> Section:
    ident = result.identifiability
    blocks: list = [Paragraph(
        f"{len(ident.identifiable)} of {len(ident.candidates)} candidate parameters are "
        f"identifiable from this data; the condition number of the column-scaled "
        f"identification Jacobian is {format_number(ident.condition_number)}. The singular "
        f"values below fall off where the data stops telling parameters apart.")]
    if len(ident.singular_values):
        blocks.append(Plot("singular-values", "Singular values of the scaled identification "
                           "Jacobian (log scale)", partial(figures.singular_values, ident)))
    if ident.unidentifiable:
        rows = tuple((name, relations_in_units(reason, result))
                     for name, reason in ident.unidentifiable.items())
        blocks.append(Details("not-identifiable", f"{len(rows)} parameters not identifiable, "
                              f"held at nominal, with the reason",
                              (Table("not-identifiable", "Not identifiable, held at nominal",
                                     ("parameter", "why"), rows),)))
    else:
        blocks.append(Paragraph("Every candidate parameter is identifiable.", "note"))
    if ident.combinations:
        blocks.append(Table("combinations", "Base-parameter combinations (only these sums or "
                            "differences are determined)", ("combination",),
                            tuple((relations_in_units(c, result),)
                                  for c in ident.combinations)))
    return Section("identifiability", "Identifiability", tuple(blocks))


def parameters_section(result: CalibrationResult) -> Section:
    units = display_units(result.units)
    geometric = {p.name: p for p in (getattr(result, "parameters_geometric", None) or ())
                 if hasattr(p, "estimate")}
    with_geometric = bool(geometric) and bool(result.effects)

    def row(p) -> tuple[str, ...]:
        scale = units.scale(p.quantity)
        decimals = parameter_decimals(units, p.quantity)
        change_text = format_fixed((p.estimate - p.nominal) / scale, decimals)
        if change_text not in ("0",) and not change_text.startswith("-"):
            change_text = "+" + change_text
        cells = [p.name, units.unit_name(p.quantity) or "-",
                 format_fixed(p.nominal / scale, decimals),
                 format_fixed(p.estimate / scale, decimals), change_text,
                 format_number(None if p.std is None else p.std / scale, 3)]
        if with_geometric:
            other = geometric.get(p.name)
            cells.append("-" if other is None else format_fixed(other.estimate / scale, decimals))
        return tuple(cells)

    header = ["parameter", "unit", "nominal", "estimate", "change", "standard error"]
    numeric = [False, False, True, True, True, True]
    if with_geometric:
        header.append("estimate, geometric fit alone")
        numeric.append(True)
    identified = [p for p in result.parameters if p.identifiable]
    held = [p for p in result.parameters if not p.identifiable]
    prior = getattr(result, "prior", None)
    use = getattr(prior, "use", None)
    fleet = use is not None and use.source != "tolerance"
    against = ("the population of robots of this model the fleet prior holds (the "
               "tolerances where it says nothing)" if fleet else "its tolerance")
    blocks: list = [Table("parameters", "Identified geometric parameters", tuple(header),
                          tuple(row(p) for p in identified), numeric=tuple(numeric)),
                    Paragraph(f"Standard errors come from the posterior covariance of the fit "
                              f"(each parameter weighed against {against}), counting "
                              f"repeated readings once.", "note")]
    if use is not None and use.offered is not None:
        said = use.sentence
        blocks.append(Paragraph(f"{said[:1].upper()}{said[1:]}.", "note"))
    if prior is not None and prior.dominated:
        listed = ", ".join(f"{name} ({100 * prior.data_share[name]:.0f}% from the data)"
                           for name in prior.dominated)
        source = "the fleet's population" if fleet else "the tolerances"
        blocks.append(Paragraph(f"Prior-dominated: {listed}. Their estimates say more about "
                                f"{source} than about this robot: the data barely "
                                f"tell them apart from other parameters or the placement.",
                                "note"))
    if held:
        reasons = tuple(row(p)[:3] + (relations_in_units(p.reason or "not identifiable",
                                                         result),) for p in held)
        blocks.append(Details("parameters-held", f"{len(held)} parameters held at nominal "
                              f"(the data cannot determine them)",
                              (Table("parameters-held", "Held at nominal",
                                     ("parameter", "unit", "nominal", "why"), reasons,
                                     (True,) * len(reasons), (False, False, True, False)),)))
    return Section("parameters", "Parameters", tuple(blocks))


def errors_section(result: CalibrationResult) -> Section:
    units = display_units(result.units)
    unit = units.length
    header = ("dataset", "role", "errors", "RMS nominal", "RMS geometric", "RMS final",
              "95th percentile final", "99th percentile final", "max final")
    rows = []
    groups = [("fit", result.residuals)]
    if result.validation_residuals:
        groups.append(("validation", result.validation_residuals))
    for role, residuals in groups:
        for r in residuals:
            rows.append(_error_row(dataset_name(r), role, [errors_of(r, m) for m in
                                                   ("nominal", "geometric", "final")], units))
        if len(residuals) > 1:
            rows.append(_error_row(f"all {role} data", role, [pooled(residuals, m) for m in
                                                              ("nominal", "geometric", "final")],
                                   units))
    blocks: list = [
        Paragraph("Nominal: the robot as designed, with only the instrument placement fitted. "
                  "Geometric: after the geometric calibration. Final: with the effects that "
                  "diagnosis added (equal to geometric when it added none). Percentiles are "
                  "of the error magnitude."),
        Table("errors", f"Error per dataset [{unit}]", header, tuple(rows),
              numeric=(False, False) + (True,) * 7),
    ]
    plot_groups = tuple((f"{role} data", residuals) for role, residuals in groups if residuals)
    if plot_groups:
        blocks.append(Plot("error-histogram", "Histogram of the error magnitude before "
                           "(nominal robot) and after calibration, logarithmic bins",
                           partial(kind_figures.magnitude_histogram, plot_groups, units)))
        blocks.append(Plot("error-distribution", "Cumulative distribution of the error "
                           "magnitude (log scale): the further left, the better",
                           partial(figures.error_distribution, plot_groups, units)))
    for role, residuals in groups:
        blocks += kind_blocks(result, role, residuals, units)
    blocks += unexplained_blocks(result, units)
    return Section("errors", "Error before and after", tuple(blocks))


def kind_blocks(result: CalibrationResult, role: str, residuals: tuple, units: Units) -> list:
    """The plots each kind of data in ``residuals`` calls for, before and after."""
    blocks: list = []
    mapped = [r for r in residuals if (np.asarray(r.rows) >= 0).any()]
    names = dataset_name(mapped[0]) if len(mapped) == 1 else f"{role} data"
    if kind_figures.has_kind(residuals, "position"):
        positioned = [r for r in residuals if kind_figures.has_kind((r,), "position")]
        label = dataset_name(positioned[0]) if len(positioned) == 1 else f"{role} data"
        blocks.append(Paragraph(f"Position errors, {label} ({role})", "heading"))
        blocks.append(Plot(f"axes-{role}", f"{label} ({role}): the x, y and z parts of the "
                           f"position error before and after; a mean away from zero is a "
                           f"bias, a wide spread a scatter",
                           partial(kind_figures.position_axes, tuple(positioned), units)))
        with_joints = [r for r in positioned if r.joints is not None]
        if with_joints:
            positions = _flange_positions(result, with_joints)
            blocks.append(Plot(f"workspace-{role}", f"{label} ({role}): error magnitude "
                               f"across the workspace, at the flange positions of the "
                               f"calibrated robot; a colour gradient shows where in the cell "
                               f"the model is weakest",
                               partial(kind_figures.workspace, tuple(with_joints),
                                       tuple(positions), units, label)))
    if kind_figures.has_kind(residuals, "distance") or \
            kind_figures.has_kind(residuals, "perpendicular"):
        measured = tuple(r for r in residuals if kind_figures.has_kind((r, ), "distance")
                         or kind_figures.has_kind((r,), "perpendicular"))
        blocks.append(Paragraph(f"Lengths and perpendicularity ({role})", "heading"))
        blocks.append(Plot(f"lengths-{role}", f"{role} data: the error of each known length "
                           f"(measured minus known, L) and of the perpendicularity (AC.BD / L) "
                           f"for every placement, before and after",
                           partial(kind_figures.placement_lengths, measured, units)))
    if kind_figures.has_kind(residuals, "surface"):
        scans = tuple(r for r in residuals if kind_figures.has_kind((r,), "surface"))
        blocks.append(Paragraph(f"Distance from the sphere surface ({role})", "heading"))
        blocks.append(Plot(f"scan-{role}", f"{role} data: signed distance of each laser point "
                           f"from the sphere surface over the scan, before and after",
                           partial(kind_figures.sphere_scan, scans, units)))
    if any(r.joints is not None for r in mapped):
        blocks.append(Paragraph(f"Against the joints and over time ({role})", "heading"))
        blocks.append(Plot(f"joints-{role}", f"{names} ({role}): error magnitude against each "
                           f"joint reading before and after; structure left in the calibrated "
                           f"error is what the model still lacks",
                           partial(kind_figures.magnitude_against_joints, tuple(mapped),
                                   result.robot_nominal, units, names)))
    if mapped:
        against = " and against temperature" if any("temperature" in r.extras
                                                    for r in mapped) else ""
        blocks.append(Plot(f"order-{role}", f"{names} ({role}): error magnitude over the "
                           f"measurements in the order taken{against}; a drift or a step "
                           f"between datasets shows here",
                           partial(figures.error_over_rows, tuple(mapped), units, names)))
    return blocks


def _flange_positions(result: CalibrationResult, residuals) -> list[np.ndarray]:
    """Flange positions [m] (rows x 3, base frame) of the calibrated robot per dataset."""
    from ..model.kinematics import Kinematics

    kinematics = Kinematics(result.robot_calibrated)
    return [kinematics.flange_poses(np.asarray(r.joints, dtype=float))[:, :3, 3]
            for r in residuals]


def effects_section(result: CalibrationResult) -> Section:
    units = display_units(result.units)
    blocks: list = []
    if not result.effects:
        blocks.append(Paragraph("Diagnosis added no effect beyond the geometric model: "
                                "nothing left in the residual was explained well enough by a "
                                "candidate effect to justify its parameters."))
    blocks += _shares_blocks(result)
    for effect in result.effects:
        # a learned map follows no joint's law: its words say where it holds, no plot
        view = None if is_learned(effect.name) else effect_view(result, effect)
        title = view.title if view is not None else effect_title(effect.name)
        kind = "learned from the data, not physical" if is_learned(effect.name) \
            else "physical"
        blocks.append(Paragraph(f"{title} ({kind})", "heading"))
        if effect.summary:
            blocks.append(Paragraph(f"{effect.summary[:1].upper()}{effect.summary[1:]}"
                                    .rstrip(".") + "."))
        if view is not None and view.panels:
            blocks.append(Plot(f"effect-{effect.name}", view.caption,
                               partial(figures.effect_evidence, view, units)))
        blocks.append(_effect_parameters(result, effect))
        if effect.evidence:
            blocks.append(Table(f"evidence-{effect.name}", f"{title}: evidence",
                                ("measure", "value"),
                                tuple(_evidence_row(k, v, units)
                                      for k, v in effect.evidence.items()),
                                numeric=(False, True)))
    if result.diagnosis:
        blocks += diagnosis_blocks(result.diagnosis, units)
    return Section("effects", "Effects found", tuple(blocks))


def _shares_blocks(result: CalibrationResult) -> list:
    """The shares of the nominal fit's mean square the geometry, the physical effects and
    a learned map remove (none without effects)."""
    fit = result.fit
    parts = mean_square_shares(fit.rms_nominal, fit.rms_geometric, fit.rms_final,
                               result.effects)
    if parts is None:
        return []
    return [Table("shares", "What removes the fit's error: shares of its mean square at "
                  "nominal", ("part", "share"),
                  tuple((name, f"{100 * value:.3g} %") for name, value in parts.items()),
                  numeric=(False, True))]


def _effect_parameters(result: CalibrationResult, effect) -> Table:
    """The fitted parameters of ``effect``, in the model's order; pure angles [rad] in the
    file's angle unit, other units as in result.json."""
    order: list[str] = []
    for model, _ in effect_models_of(result, effect):
        order += [n for n in model.parameter_names() if n in effect.parameters]
    names = order + [n for n in effect.parameters if n not in order]
    def shown(name: str) -> tuple[float, str]:
        unit = effect.unit_of(name)  # a lumped term has its own (rad kg/Nm, not rad/Nm)
        if unit == "rad" and result.units.angle != "rad":
            return result.units.angle_scale, result.units.angle
        return 1.0, unit

    rows = tuple((name, format_number(effect.parameters[name] / shown(name)[0], 4),
                  format_number(None if effect.std.get(name) is None
                                else effect.std[name] / shown(name)[0], 3), shown(name)[1])
                 for name in names)
    return Table(f"effect-{effect.name}", f"{effect_title(effect.name)}: fitted parameters "
                 f"({effect.name} in result.json)",
                 ("parameter", "value", "standard error", "unit"), rows,
                 numeric=(False, True, True, False))


DIAGNOSIS_SHOWN = 5  # rejected candidates shown in the main text, strongest first
DIAGNOSIS_HEADERS = {
    "round": "round", "effect": "effect", "joints": "joints", "parameters": "parameters",
    "held": "held at zero", "remaining_norm": "independence",
    "rss_drop": "RSS drop", "bic_drop": "BIC drop", "cv_rms_before": "fold RMS before",
    "cv_rms_after": "fold RMS with it", "decision": "decision",
    "estimate": "estimate (SI units, as in result.json)",
    "extrapolation": "held-out squared error with it / without it, extrapolating folds",
    "worst_region": "extrapolating split it helps least",
    "label": "name in result.json",
    "rivals": "rivals that stand (held-out squared error where the two differ most, with it "
              "and with the rival, against neither)",
}
NUMERIC_KEYS = {"round", "parameters", "remaining_norm", "rss_drop", "bic_drop",
                "cv_rms_before", "cv_rms_after"}
# The short columns, side by side; the decision, the estimate and whatever else a
# candidate records are set under its row (a page has no room for them side by side).
DIAGNOSIS_SIDE_BY_SIDE = {"round", "effect", "joints", "parameters", "held"} | NUMERIC_KEYS


def diagnosis_blocks(diagnosis: tuple[DiagnosisRecord, ...], units: Units) -> list:
    """What diagnosis tested: the candidates added and the strongest few rejected in the
    main text, every candidate in a block folded away on screen (printed in full)."""
    entries = [entry.as_dict() for entry in diagnosis]
    is_added = [entry.outcome is Decision.ADDED for entry in diagnosis]
    added = [e for e, a in zip(diagnosis, is_added) if a]
    numbers = [(t, e) for t, e, a in zip(diagnosis, entries, is_added) if not a
               and isinstance(e.get("bic_drop"), (int, float))
               and math.isfinite(float(e["bic_drop"]))
               and int(e.get("parameters", 1) or 0) > 0]
    numbers.sort(key=lambda pair: float(pair[1]["bic_drop"]), reverse=True)
    rejected = [t for t, _ in numbers]
    strongest = rejected[:DIAGNOSIS_SHOWN]
    rounds = max((int(e.get("round", 1) or 1) for e in entries), default=1)
    shown = added + strongest
    text = (f"Diagnosis tested {len(entries)} candidates in {rounds} round"
            f"{'s' if rounds != 1 else ''} and added {len(added) or 'none'}. Below: "
            + ("the candidates added and " if added else "")
            + f"the {len(strongest)} strongest rejected (largest BIC drop); every candidate is "
              f"listed after it.")
    blocks: list = [Paragraph(text),
                    diagnosis_table(tuple(shown), units, name="diagnosis-summary",
                                    caption="Candidates added and the strongest rejected"),
                    Paragraph("RSS drop: relative fall of the sum of squared errors with the "
                              "candidate; BIC drop: that fall weighed against the parameters "
                              "it adds (positive favours the candidate); fold RMS: "
                              "cross-validated RMS of the fit data's errors before and with "
                              "it (folds of the fit readings held out in turn; the held-out "
                              "data set, where given, is a separate test and decides); "
                              "independence: 1 when the candidate acts unlike "
                              "any geometric parameter, 0 when the geometry already absorbs "
                              "it.", "note")]
    blocks.append(Details("diagnosis-all", f"All {len(entries)} candidates tested",
                          (diagnosis_table(diagnosis, units),)))
    return blocks


def diagnosis_table(diagnosis: tuple[DiagnosisRecord, ...], units: Units, *,
                    name: str = "diagnosis",
                    caption: str = "Every candidate tested by diagnosis") -> Table:
    """Candidate effects diagnosis tested, with the numbers it recorded.

    RMS values (keys holding ``rms`` that are not a relative ``drop``) are lengths [m]
    and are shown in the file's length unit; relative drops in percent.
    """
    keys: list[str] = []
    entries = [entry.as_dict() for entry in diagnosis]
    for entry in entries:
        for k, v in entry.items():
            if k not in keys and isinstance(v, (int, float, str, bool, list, tuple)):
                keys.append(k)
    lengths = {k for k in keys if "rms" in k and "drop" not in k}

    def cell(key: str, value) -> str:
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if key in lengths and number:
            return format_number(value / units.length_scale, 4) if math.isfinite(value) else "-"
        if key == "effect" and isinstance(value, str):
            return effect_title(value).lower()
        if key == "rss_drop" and number:
            return f"{100 * value:.1f} %" if math.isfinite(value) else "-"
        if key == "bic_drop" and number:
            return f"{value:.1f}" if math.isfinite(value) else "-"
        if key == "remaining_norm" and number:
            return f"{value:.3f}" if math.isfinite(value) else "-"
        if isinstance(value, (list, tuple)) and not value:
            return "-"
        return _scalar_text(value)

    rows = tuple(tuple(cell(k, entry.get(k, "")) for k in keys) for entry in entries)
    header = tuple(f"{DIAGNOSIS_HEADERS.get(k, k)} [{units.length}]" if k in lengths
                   else DIAGNOSIS_HEADERS.get(k, k) for k in keys)
    muted = tuple(entry.outcome is not Decision.ADDED for entry in diagnosis)
    return Table(name, caption, header, rows, muted,
                 tuple(k in NUMERIC_KEYS for k in keys),
                 below=tuple(k not in DIAGNOSIS_SIDE_BY_SIDE for k in keys))


def sphere_section(result: CalibrationResult) -> Section | None:
    spheres = [r for r in result.residuals + result.validation_residuals
               if r.kind in INSTRUMENTS and INSTRUMENTS[r.kind].model.sphere]
    if not spheres:
        return None
    units = display_units(result.units)
    laser = {k: v for k, v in result.mounted.items()
             if any(word in k.lower() for word in ("laser", "origin", "direction", "beam"))}
    laser = laser or dict(result.mounted)
    blocks: list = [Paragraph(
        "The laser's reference point p0 and beam direction n are in the flange frame; the "
        "sphere centre c is in the robot base frame. Each reading l puts the laser spot at "
        "T (p0 + l n), which must lie on the sphere: |T (p0 + l n) - c| = R.")]
    blocks.append(_values_table("laser", "Laser on the flange (fitted)",
                                [(k, v, sd) for k, (v, sd) in laser.items()], units))
    for r in spheres:
        centre = [(k, v, None) for k, v in result.placement.items() if _belongs(k, r.label)]
        if centre:
            blocks.append(_values_table(f"sphere-{r.label}",
                                        f"Sphere centre, {dataset_name(r)} (fitted)",
                                        centre, units))
        stats = ErrorStats.of(errors_of(r, "final"))
        blocks.append(Paragraph(
            f"{dataset_name(r)}: {stats.count} readings; distance from the sphere surface after "
            f"calibration {format_number(stats.rms / units.length_scale)} {units.length} RMS, "
            f"{format_number(stats.max / units.length_scale)} {units.length} at most."))
    return Section("sphere", "Sphere and laser", tuple(blocks))


def instrument_section(result: CalibrationResult) -> Section | None:
    if not result.mounted and not result.placement:
        return None
    units = display_units(result.units)
    blocks: list = [Paragraph("Mounted: what is fixed to the robot (probe, reflector, laser), "
                              "shared by all datasets. Placement: where the instrument sits in "
                              "the room, fitted per dataset.", "note")]
    if result.mounted:
        blocks.append(_values_table("mounted", "Mounted on the robot",
                                    [(k, v, sd) for k, (v, sd) in result.mounted.items()], units))
    if result.placement:
        blocks.append(_values_table("placement", "Instrument placement",
                                    [(k, v, None) for k, v in result.placement.items()], units))
    return Section("instrument", "Instrument", tuple(blocks))


# ----------------------------------------------------------------------------- helpers


def _error_row(label: str, role: str, errors: list[np.ndarray], units: Units) -> tuple[str, ...]:
    scale = units.length_scale
    nominal, geometric, final = (ErrorStats.of(e) for e in errors)
    return (label, role, str(final.count), format_number(nominal.rms / scale),
            format_number(geometric.rms / scale), format_number(final.rms / scale),
            format_number(final.p95 / scale), format_number(final.p99 / scale),
            format_number(final.max / scale))


def _values_table(name: str, caption: str, entries: Sequence[tuple[str, float, float | None]],
                  units: Units) -> Table:
    rows = []
    for key, value, std in entries:
        quantity = quantity_of_placement(key)
        scale = units.scale(quantity)
        rows.append((key, format_fixed(value / scale, parameter_decimals(units, quantity)),
                     format_number(None if std is None else std / scale, 3),
                     units.unit_name(quantity) or "-"))
    return Table(name, caption, ("name", "value", "standard error", "unit"), tuple(rows),
                 numeric=(False, True, True, False))


EVIDENCE_TITLES = {
    "rms_drop": "fall of the RMS on the fit data",
    "bic_drop": "BIC drop (positive favours the effect)",
    "cv_rms_before": "fold RMS of the fit data without it (cross-validated)",
    "cv_rms_after": "fold RMS of the fit data with it (cross-validated)",
    "fit_rms_without": "fit RMS without it",
    "extrapolation": "fold squared error with / without it, extrapolating folds",
    "length_scale": "length scale, of the trained span",
    "smoothing": "smoothing (against the kernel's unit diagonal)",
}


def _evidence_row(key: str, value: float, units: Units) -> tuple[str, str]:
    """An evidence entry in words; RMS values (not relative drops) are lengths [m], shown
    in file units, relative drops in percent."""
    title = EVIDENCE_TITLES.get(key, key)
    if "rms" in key and "drop" not in key:
        return f"{title} [{units.length}]", format_number(value / units.length_scale, 4)
    if key == "rms_drop":
        return title, f"{100 * value:.1f} %"
    if key == "bic_drop":
        return title, f"{value:.1f}"
    return title, format_number(value, 4)


def _belongs(name: str, label: str) -> bool:
    """True when placement unknown ``name`` is dataset ``label``'s (``label`` + separator)."""
    return name.startswith(label) and len(name) > len(label) and name[len(label)] in "/.:_"


def _scalar_text(value) -> str:
    if isinstance(value, float):
        return format_number(value, 6) if math.isfinite(value) else "-"
    if isinstance(value, (list, tuple)):
        return ", ".join(_scalar_text(v) for v in value)
    return str(value)

