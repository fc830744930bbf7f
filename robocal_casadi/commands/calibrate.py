"""Identify the robot model from datasets; write result.json, robot_calibrated.yaml, report.html.

All datasets share one robot file and are solved together. The geometric DH model is
identified first (what the data cannot determine is reported, with the reason, and held
at nominal); then, unless --no-diagnose, the residual is tested against effects the model
lacks (joint compliance, periodic joint errors, gear-ratio errors, thermal drift) and
those the data support are added. --validate datasets are held out: the robot and what
is mounted on it come from the calibration, the placement of the instrument is fitted
again on them.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from ..calibration import METHODS
from ..calibration.drive_hints import drive_lines, was_added
from ..calibration.identification import CALIBRATION_LOSSES
from ..calibration.outliers import rejected_lines
from ..common.units import Units, display_units
from ..effects import is_learned
from ..effects.effect_model import delivered_lines
from ..errors import InputError
from ..formats import profiles
from ..instruments.datasets import load_dataset
from ..instruments.held_truth import held_out_truth_note
from ..job.run import JobOptions, ReportOptions, run_job
from ..results import (
    CalibrationResult,
    Decision,
    PredictedAccuracy,
    ProfileCost,
    mean_square_shares,
)
from .arguments import add_allow_outside_data, add_force, not_replacing_inputs, output_folder
from .console import summarise


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("datasets", nargs="+", type=Path, metavar="DATASET.yaml")
    parser.add_argument("--validate", action="append", type=Path, default=[],
                        metavar="VAL.yaml",
                        help="a held-out dataset evaluated with the calibrated model; one "
                        "file per flag, repeat it for more")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR",
                        help="output folder (replaced as a whole when the run succeeds)")
    parser.add_argument("--no-diagnose", action="store_true",
                        help="stop after the geometric model")
    parser.add_argument("--method", choices=METHODS, default="lm",
                        help="lm: Levenberg-Marquardt (default); ipopt; linearised: iterated "
                             "A dx = b; two_stage: angles then lengths")
    parser.add_argument("--loss", choices=CALIBRATION_LOSSES, default="robust",
                        help="robust (default): readings with gross errors are found, listed "
                             "and set aside; linear: every reading kept, plain least squares; "
                             "huber: every reading kept, large residuals down-weighted")
    parser.add_argument("--select-growth", type=float, default=None, metavar="G",
                        help="drop units of data (bar placements, readings) that grow the "
                             "condition number by more than the fraction G, e.g. 0.05")
    parser.add_argument("--max-iterations", type=int, default=200, metavar="N",
                        help="iterations allowed to the geometric fit (default 200)")
    add_model_options(parser)
    parser.add_argument("--no-report", action="store_true", help="skip report.html")
    add_force(parser)
    add_allow_outside_data(parser)
    add_report_options(parser)


def add_model_options(parser: argparse.ArgumentParser) -> None:
    """``--rule``, ``--profile`` and ``--prior`` (calibrate and fleet)."""
    parser.add_argument("--prior", type=Path, default=None, metavar="PRIOR.yaml",
                        help="a fleet prior of this robot model (robocal prior) in place of "
                             "the tolerances; a robot whose data contradict it is told so "
                             "and calibrated with the tolerance prior")
    parser.add_argument("--rule", choices=("prior", "fraction"), default="prior",
                        help="prior (default): every parameter not exactly undeterminable, "
                             "weighed against its tolerance (maximum a posteriori); fraction: "
                             "least squares, parameters with under 1%% of their effect their "
                             "own held at nominal")
    sets = "; ".join(f"{p.name}: {p.phrase}" for p in profiles())
    parser.add_argument("--profile", choices=[p.name for p in profiles()], default=None,
                        help=f"fit only the robot parameters this controller accepts ({sets}) "
                             "and report what that costs")


def add_report_options(parser: argparse.ArgumentParser) -> None:
    """``--pdf`` and the report's fields (calibrate and fleet)."""
    parser.add_argument("--pdf", action="store_true",
                        help="also write report.pdf (printed by headless Chromium when "
                             "installed)")
    report = parser.add_argument_group(
        "report fields", "shown at the top of report.html; each overrides the same field "
        "of a dataset file's report: block")
    for option, meta, text in (("--customer", "NAME", "customer"),
                               ("--robot-serial", "SERIAL", "robot serial number"),
                               ("--instrument", "TEXT", "measuring instrument"),
                               ("--operator", "NAME", "who measured"),
                               ("--date", "DATE", "date of measurement"),
                               ("--logo", "FILE", "logo image (PNG, JPEG or SVG)")):
        report.add_argument(option, metavar=meta, help=text)
    report.add_argument("--report-templates", type=Path, metavar="DIR",
                        help="folder of Jinja2 templates replacing the report's own "
                             "(report.html.j2, blocks.html.j2, brand.html.j2, report.css)")


def summary(result: CalibrationResult, *, diagnosed: bool = True) -> str:
    """A few lines for the terminal: what was identified and the error before and after
    (``diagnosed``: whether the residual was tested for effects the model lacks)."""
    units = display_units(result.units)  # one length unit, mm, in the whole block
    s = units.length_scale
    ident = result.identifiability
    rows = sum(len(r.errors_final) for r in result.residuals)
    lines = [f"WARNING: {result.warning}"] if result.warning else []
    delivery = result.delivery
    if delivery is not None and delivery.refused:
        lines.insert(0, f"NOT BETTER THAN DOING NOTHING: {delivery.reason}")
    use = result.prior.use if result.prior is not None else None
    if use is not None and use.sentence:
        lines.append(use.sentence)
    lines += [f"{rows} measurements from {', '.join(result.datasets)}; "
             f"{len(ident.identifiable)} of {len(ident.candidates)} parameters identifiable "
             f"(condition number {result.condition_number:.4g})"]
    fit = result.fit
    lines.append(f"fit RMS [{units.length}]: nominal {fit.rms_nominal / s:.4g}, geometric "
                 f"{fit.rms_geometric / s:.4g}, final {fit.rms_final / s:.4g}")
    lines += validation_lines(result, units)
    lines += rejected_lines(result.rejected, units)
    for label, dropped in result.selection.items():
        if dropped:
            lines.append(f"data selection dropped {len(dropped)} unit(s) of {label}: "
                         f"{', '.join(map(str, dropped))}")
    lines += _effect_lines(result)
    if not diagnosed:
        lines.append("diagnosis: not run (--no-diagnose); the residual was not tested for "
                     "effects the model lacks")
    elif not result.effects:
        lines.append("effects: none added")
    if result.effects:
        lines.append(f"recommended model: {result.recommended} ({result.recommendation})")
    profile: ProfileCost | None = result.profile  # the result types it loosely
    if profile is not None:
        lines.append(profile.sentence(units, result.fit, result.validation))
    if result.delivered is not None:
        lines += delivered_lines(result.delivered, s, units.length,
                                 kept=bool(result.held_out_set_aside))
    if result.predicted_accuracy is not None:
        lines += result.predicted_accuracy.sentence(s, units.length).splitlines()
    lines += _refusal_lines(result)
    left = result.remainder
    if result.unexplained is not None:
        taken = any(is_learned(e.name) for e in result.effects)
        lines.append("unexplained: " + result.unexplained.sentence(s, units.length, left)
                     + ("; the learned map corrects it inside the region it was trained on"
                        if taken else ""))
    elif diagnosed and (left is None or left.is_noise):
        lines.append("unexplained: none (what remains is consistent with noise)")
    elif diagnosed:
        lines.append("unexplained: no structure the diagnosis tests for is significant")
    if left is not None:
        variables = () if result.unexplained is None else result.unexplained.variables
        lines.append("remains: " + left.sentence(units, variables))
    return "\n".join(lines)


def validation_lines(result: CalibrationResult, units: Units) -> list[str]:
    """The held-out RMS over every held-out reading first; then, where gross errors were
    set aside, the same over the readings kept, with their count."""
    if result.validation is None:
        return []
    s = units.length_scale

    def figures(v) -> str:
        return (f"nominal {v.rms_nominal / s:.4g}, geometric {v.rms_geometric / s:.4g}, "
                f"final {v.rms_final / s:.4g}")

    aside = result.held_out_set_aside
    if not aside or result.validation_all is None:
        return [f"validation RMS [{units.length}]: {figures(result.validation)}"]
    kept = sum(len(r.joints) if r.joints is not None else len(r.errors_final)
               for r in result.validation_residuals)
    return [f"validation RMS [{units.length}] over all {kept + aside} held-out readings: "
            f"{figures(result.validation_all)}",
            f"validation RMS [{units.length}] over the {kept} kept ({aside} set aside as gross "
            f"errors): {figures(result.validation)}"]


def _effect_lines(result: CalibrationResult) -> list[str]:
    """Each effect added, physical or learned, and the shares of the nominal fit's mean
    square that geometry, physical effects and a learned map took."""
    lines = []
    for effect in result.effects:
        kind = "learned" if is_learned(effect.name) else "physical"
        lines.append(f"effect ({kind}): {effect.summary or effect.name}")
    fit = result.fit
    parts = mean_square_shares(fit.rms_nominal, fit.rms_geometric, fit.rms_final,
                               result.effects)
    if parts is not None:
        lines.append("shares of the nominal fit's mean square: " + ", ".join(
            f"{name} {100 * value:.3g}%" for name, value in parts.items()))
    return lines


def _refusal_lines(result: CalibrationResult) -> list[str]:
    """The effects diagnosis refused for a reason the user should hear (stand-ins of sizes
    no robot shows, taken out again, confounded with a rival)."""
    lines = []
    stand_ins = _rejected(result, Decision.IMPLAUSIBLE)
    if stand_ins:
        lines.append("not added, sizes no real robot shows (they stand in for something the "
                     f"library does not name): {', '.join(stand_ins)}")
    lines += drive_lines(result)
    removed = _rejected(result, Decision.TAKEN_OUT)
    if removed:
        lines.append("added, then taken out again (with the later effects in, it no longer "
                     f"helps): {', '.join(removed)}")
    lines += _covered_lines(result)
    confounded = _rejected(result, Decision.CONFOUNDED)
    if confounded:
        lines.append("not added, confounded with a rival on these data (held-out squared "
                     "error where the two differ most, with it / with the rival, against "
                     "neither): " + ", ".join(_with_rivals(result, confounded)))
    return lines


def _with_rivals(result: CalibrationResult, labels: list[str]) -> list[str]:
    """Each confounded candidate of ``labels`` with the rivals it was last refused for and
    their figures on the units that separate them (``CandidateTest.rivals``)."""
    last: dict[str, tuple] = {}
    for test in result.diagnosis:
        if test.outcome is Decision.CONFOUNDED:
            last[test.label or test.effect] = tuple(test.as_dict().get("rivals", ()))
    out = []
    for label in labels:
        figures = "; ".join(
            f"{name}: no data separate them" if not math.isfinite(own)
            else f"{name}: x{own:.3g} / x{rival:.3g}" for name, own, rival in last.get(label, ()))
        out.append(f"{label} ({figures})" if figures else label)
    return out


def _covered_lines(result: CalibrationResult) -> list[str]:
    """The physical effects taken out once the learned map was in, each with the held-out
    figures that decided it."""
    s, unit = result.units.length_scale, result.units.length
    gone = [(t.label or t.effect, t.as_dict()) for t in result.diagnosis
            if t.outcome is Decision.COVERED]
    if not gone:
        return []
    return ["taken out once the learned map was in (the map covers what they explained): "
            + "; ".join(f"{label} (held-out RMS {e['cv_rms_after'] / s:.4g} {unit} with it, "
                        f"{e['cv_rms_before'] / s:.4g} without it, each with its map; "
                        f"BIC drop {e['bic_drop']:.3g})" for label, e in gone)]


def summary_fields(result: CalibrationResult, *, diagnosed: bool = True) -> dict:
    """The terminal summary's facts as JSON fields (lengths in the robot file's unit)."""
    s = result.units.length_scale

    def rms(fit) -> dict | None:
        return None if fit is None else {"nominal": fit.rms_nominal / s,
                                         "geometric": fit.rms_geometric / s,
                                         "final": fit.rms_final / s}

    ident = result.identifiability
    return {"datasets": list(result.datasets), "unit": result.units.length,
            "identifiable": len(ident.identifiable), "candidates": len(ident.candidates),
            "condition_number": float(result.condition_number), "fit_rms": rms(result.fit),
            "validation_rms": rms(result.validation), "diagnosed": diagnosed,
            "effects": [e.name for e in result.effects],
            "learned_effects": [e.name for e in result.effects if is_learned(e.name)],
            "recommended": result.recommended, "warning": result.warning or None,
            "delivered_model": None if result.delivered is None else result.delivered.model,
            "predicted_accuracy": None if result.predicted_accuracy is None else {
                "rms": result.predicted_accuracy.rms / s, "p95": result.predicted_accuracy.p95 / s,
                "max": result.predicted_accuracy.max / s,
                "rms_band": None if result.predicted_accuracy.band is None else [
                    v / s for v in result.predicted_accuracy.band],
                **_regions(result.predicted_accuracy, s)}}


def _regions(predicted: PredictedAccuracy, s: float) -> dict:
    """The region of the summary's predicted figure, the nominal robot's over it, and
    the box figure with the parameters that carry its difference (robot file units)."""
    return {"region": predicted.region_kind,
            "nominal_rms": None if predicted.nominal is None else predicted.nominal.rms / s,
            "box_rms": None if predicted.box is None else predicted.box.rms / s,
            "unseen": [u.name for u in predicted.unseen]}


def _rejected(result: CalibrationResult, outcome: Decision) -> list[str]:
    """Labels of the candidates diagnosis decided ``outcome`` for and never added."""
    out: list[str] = []
    for test in result.diagnosis:
        label = test.label or f"{test.effect}{list(test.joints)}"
        # a unit refused in one round and added in a later one is no refusal
        if test.outcome is outcome and not was_added(result, test.effect, test.joints) \
                and label not in out:
            out.append(label)
    return out


REPORT_FIELDS = ("customer", "robot_serial", "instrument", "operator", "date")


def command_line_info(args: argparse.Namespace):
    """The report's fields the command line gives, the logo and the templates checked."""
    from ..report.info import ReportInfo, check_logo

    given = {name: getattr(args, name) for name in REPORT_FIELDS if getattr(args, name, None)}
    if getattr(args, "logo", None):
        given["logo"] = check_logo(args.logo)
    if args.report_templates is not None and not args.report_templates.is_dir():
        raise InputError("is not a folder of report templates", file=args.report_templates,
                         where="--report-templates")
    return ReportInfo(**given)


def report_info(args: argparse.Namespace, datasets: list):
    """The report's customer fields: the datasets' ``report:`` blocks in turn, then the
    command-line options, each overriding what came before."""
    from ..report.info import ReportInfo, info_from_dataset_file

    info = ReportInfo()
    for dataset in datasets:
        info = info.merged(info_from_dataset_file(dataset.path))
    return info.merged(command_line_info(args))


def read_options(args: argparse.Namespace) -> list[Path]:
    """The files and folders the command line names for reading: the datasets, the
    held-out datasets, the logo and the report templates."""
    named = [*args.datasets, *args.validate, args.logo, args.report_templates,
             getattr(args, "prior", None)]
    return [Path(p) for p in named if p is not None]


def fleet_prior_option(args: argparse.Namespace):
    """The ``--prior`` file loaded (None when not given); ``--rule fraction`` refused
    with it."""
    if getattr(args, "prior", None) is None:
        return None
    if args.rule != "prior":
        raise InputError("a fleet prior weighs the estimate: it needs --rule prior",
                         where="--prior")
    from ..calibration.population_prior import load_prior

    return load_prior(args.prior)


def run(args: argparse.Namespace) -> int:
    output_folder(args.out, verb="calibrate", force=args.force, inputs=read_options(args))
    if args.max_iterations < 1:
        raise InputError(f"expected a positive count, got {args.max_iterations}",
                         where="--max-iterations")
    if args.select_growth is not None and not (math.isfinite(args.select_growth)
                                               and args.select_growth > 0):
        raise InputError(f"expected a positive fraction, got {args.select_growth}",
                         where="--select-growth")
    outside = args.allow_outside_data
    datasets = [load_dataset(p, allow_outside_data=outside) for p in args.datasets]
    validation = [load_dataset(p, allow_outside_data=outside) for p in args.validate]
    seen: dict = {}
    for dataset in datasets + validation:
        key = dataset.path.resolve()
        if key in seen:
            raise InputError(f"the same dataset is given twice ({seen[key]} and {dataset.path}); "
                             "a dataset is either fitted or held out, once", file=dataset.path)
        seen[key] = dataset.path
    info = report_info(args, datasets + validation)
    not_replacing_inputs(args.out, [*read_options(args), *(p for d in datasets + validation
                                                           for p in (d.path, d.data_path,
                                                                     d.robot_path))])
    other_robot = held_out_truth_note(datasets, validation)
    options = JobOptions(diagnose=not args.no_diagnose, method=args.method, loss=args.loss,
                         select_growth=args.select_growth, max_iterations=args.max_iterations,
                         rule=args.rule, profile=args.profile, progress=sys.stderr.isatty(),
                         fleet_prior=fleet_prior_option(args),
                         notes=(other_robot,) if other_robot else ())
    report = ReportOptions(report=not args.no_report, pdf=args.pdf, info=info,
                           templates=args.report_templates)
    outcome = run_job(datasets, validation, options, args.out, report, verb="calibrate",
                      progress=options.progress)
    result = outcome.result
    print(summary(result, diagnosed=not args.no_diagnose))
    if other_robot:  # after the summary, whose first line may say the run was refused
        print(f"NOTE: {other_robot}")
    written = [name for name in outcome.written if not name.startswith(".")]
    print(f"wrote {args.out}/: {', '.join(written)}")
    summarise(args, **summary_fields(result, diagnosed=not args.no_diagnose),
              out=str(args.out), written=written, notes=list(result.notes))
    return outcome.exit_status
