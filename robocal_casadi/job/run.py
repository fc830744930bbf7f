"""The whole calibration job: calibrate, diagnose, choose what is delivered, write.

``robocal calibrate``, ``robocal demo``, a fleet's robot task and the Python API all run
this one job, so their results are the same, key by key:

1. ``calibrate`` (geometry, then the effects diagnosis adds), restricted to a
   controller's parameter set when a ``profile`` is given;
2. ``job.choice.choose``: the best geometry-only model for ``robot_calibrated.yaml``, or
   doing nothing when the calibration is not better (``recommended`` ``nominal`` or
   ``instrument_only``, exit status 3);
3. ``write``: the files staged in a new folder; every accuracy figure stated about a
   delivered file is computed by reading that file back and running the forward
   kinematics ``robocal fk`` runs; the predicted accuracy over the work cell; then
   ``result.json`` and the report; the folder moved into place as a whole.

Each step runs the linear algebra library (OpenBLAS, MKL, ...) on one thread. A matrix
product split over several threads adds its terms in another order, so the last digits
of every estimate would depend on the machine's cores, and a fleet's worker processes
(started with one thread each) would write other bytes than ``robocal calibrate`` for the
same robot. On one thread every caller writes the same ``result.json``; the products of
a calibration are too small for more threads to pay for starting them.
"""

from __future__ import annotations

import functools
import json
import shutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import ParamSpec, TypeVar

import numpy as np
from threadpoolctl import threadpool_limits

from ..calibration.evaluation import evaluate, held_out
from ..calibration.identification import calibrate as _calibrate
from ..calibration.outliers import kept_datasets
from ..calibration.population_prior import PopulationPrior, write_posterior
from ..common.memory import release_freed
from ..common.output import atomic_directory
from ..common.output import json_safe as _clean
from ..common.progress import reports_stages, stage
from ..effects.effect_model import EFFECTS_FILE, load_effects, save_effects
from ..errors import ArgumentError
from ..formats import profile_parameters
from ..model.robot import load_robot, save_robot
from ..report.errors_table import write_errors_csv
from ..report.info import ReportInfo
from ..results import CalibrationResult, CandidateFigures, Delivered, ProfileCost
from .accuracy import statement, work_cell
from .choice import choose

P = ParamSpec("P")
R = TypeVar("R")
ROBOT_FILE = "robot_calibrated.yaml"
REFUSED = 3  # exit status: the calibration is not better than doing nothing


@dataclass(frozen=True)
class JobOptions:
    """How to calibrate (the options of ``calibration.calibrate``) and, with
    ``profile``, the controller whose parameter set alone is fitted; ``effects`` declared
    from the start and ``parameters`` (the robot parameters that may be fitted; None: all)
    as ``calibration.calibrate`` takes them."""

    diagnose: bool = True
    method: str = "lm"
    loss: str = "robust"
    select_growth: float | None = None
    max_iterations: int = 200
    rule: str = "prior"
    profile: str | None = None
    progress: bool = False
    effects: Sequence = ()
    parameters: Sequence[str] | str | None = None
    fleet_prior: PopulationPrior | None = None  # in place of the tolerance prior
    notes: tuple[str, ...] = ()  # what a reader must know about the inputs (result.json)

    def calibrate_options(self) -> dict:
        return dict(diagnose=self.diagnose, method=self.method, loss=self.loss,
                    select_growth=self.select_growth, max_iterations=self.max_iterations,
                    rule=self.rule, progress=self.progress, effects=self.effects,
                    fleet_prior=self.fleet_prior)


@dataclass(frozen=True)
class ReportOptions:
    """What is written beside the result: the report (``pdf`` too), its customer fields
    ``info``, a folder of report ``templates``, and files of an earlier result to ``keep``."""

    report: bool = True
    pdf: bool = False
    info: ReportInfo | None = None
    templates: Path | None = None
    keep: tuple[str, ...] = ()


@dataclass(frozen=True)
class JobOutcome:
    """A finished job: the ``result`` as written into ``out`` and the ``written`` files."""

    result: CalibrationResult
    out: Path | None
    written: tuple[str, ...] = ()

    @property
    def exit_status(self) -> int:
        """0, or 3 when the calibration is not better than doing nothing."""
        delivery = self.result.delivery
        return REFUSED if delivery is not None and delivery.refused else 0

    def __repr__(self) -> str:
        return (f"JobOutcome(out={str(self.out)!r}, recommended={self.result.recommended!r}, "
                f"written={list(self.written)})")


def on_one_blas_thread(function: Callable[P, R]) -> Callable[P, R]:
    """``function`` run with the linear algebra library on one thread (the module
    docstring says why); the caller's setting is restored after."""
    @functools.wraps(function)
    def run(*args: P.args, **kwargs: P.kwargs) -> R:
        with threadpool_limits(limits=1, user_api="blas"):
            return function(*args, **kwargs)

    return run


@on_one_blas_thread
def calibrate_job(datasets: Sequence, validation: Sequence = (),
                  options: JobOptions = JobOptions()) -> CalibrationResult:
    """Steps 1 and 2: the calibration with its delivery chosen (nothing written)."""
    datasets, validation = list(datasets), list(validation)
    if options.profile is None:
        result = _calibrate(datasets, validation, parameters=options.parameters,
                            **options.calibrate_options())
    else:
        result = _profiled(datasets, validation, options)
    if options.notes:
        result = replace(result, notes=tuple(options.notes) + tuple(result.notes))
    return deliver(result, datasets, validation)


def deliver(result: CalibrationResult, datasets: Sequence,
            validation: Sequence = ()) -> CalibrationResult:
    """``result`` with its ``delivery`` chosen: ``robot_calibrated`` the delivered geometry,
    ``recommended`` and its reason updated when doing nothing is better. Judged on the
    readings the calibration kept (gross errors set aside)."""
    datasets, validation = _kept(result, datasets, validation)
    with stage("delivery: the geometry a controller runs"):
        delivery = choose(result, datasets, validation)
    recommendation = result.recommendation
    if delivery.refused:
        recommendation = delivery.reason
    return replace(result, delivery=delivery, robot_calibrated=delivery.robot,
                   recommended=delivery.recommended, recommendation=recommendation)


@reports_stages(default=False)
def run_job(datasets: Sequence, validation: Sequence = (), options: JobOptions = JobOptions(),
            out: Path | None = None, report: ReportOptions = ReportOptions(), *,
            verb: str = "calibrate", progress: bool = False) -> JobOutcome:
    """The whole job; with ``out``, the files written there, the folder's marker naming
    ``verb`` (see the module docstring). ``progress``: every stage on a terminal (the
    calibration's own stages with ``options.progress``)."""
    del progress  # read by ``reports_stages``
    result = calibrate_job(datasets, validation, options)
    if out is None:
        return JobOutcome(measured(result, datasets, validation), None)
    return write(result, datasets, validation, Path(out), report, verb=verb)


@on_one_blas_thread
def measured(result: CalibrationResult, datasets: Sequence, validation: Sequence = (),
             robot_file: Path | None = None, effects_folder: Path | None = None
             ) -> CalibrationResult:
    """``result`` with ``delivered`` (RMS [m] each output gives on the fit and held-out
    data) and ``predicted_accuracy``, computed from the files as written when given
    (``robot_file``; ``effects_folder`` holding ``effects_calibrated.yaml``), else from
    the models in memory."""
    datasets, validation = _kept(result, datasets, validation)
    robot = load_robot(robot_file) if robot_file is not None else result.robot_calibrated
    delivery = result.delivery
    if delivery is None:
        raise ArgumentError("expected a result whose delivery is chosen (calibrate_job or "
                            "deliver), got one without", argument="result")
    mounted = delivery.candidate(delivery.delivered).mounted
    figures: dict[str, dict[str, float]] = {ROBOT_FILE: {}}
    errors: dict[str, np.ndarray] = {}
    for role, data in (("fit", datasets), ("validation", validation)):
        if data:
            problem, x = evaluate(robot, list(data), (), mounted) if role == "fit" else \
                held_out(robot, list(data), (), mounted, anchors=datasets)
            figures[ROBOT_FILE][role] = problem.rms(x)
            errors[role] = np.concatenate(problem.errors(x))
    with_effects = _with_effects(result, robot, datasets, validation, effects_folder)
    structured = _effects_left_out(result, robot)
    names = list(mounted)[:3]  # the instrument's point on the flange comes first
    point = [mounted[n] for n in names] if len(names) == 3 else [0.0, 0.0, 0.0]
    region, region_kind = work_cell(result, datasets)
    effects, effects_point = _effect_model(result, names)
    predicted = statement(
        result, robot, point, names if len(names) == 3 else (), structured, region,
        region_kind, effects=effects, effects_point=effects_point,
        nominal=_nominal(delivery, names), instrument=result.residuals[0].kind
        if result.residuals else "", held_out=figures[ROBOT_FILE].get("validation")
    ) if region is not None else None
    if delivery.refused:
        structured = 0.0  # nothing calibrated: no posterior to propagate
        predicted = None
    delivered = Delivered(model=delivery.delivered, robot_file=figures[ROBOT_FILE],
                          with_effects=with_effects, mounted=dict(mounted), errors=errors,
                          basis=delivery.basis, reason=delivery.reason,
                          candidates=tuple(CandidateFigures(c.name, c.fit_rms, c.held_out_rms)
                                           for c in delivery.candidates))
    return replace(result, delivered=delivered, predicted_accuracy=predicted)


def _kept(result: CalibrationResult, datasets: Sequence,
          validation: Sequence) -> tuple[list, list]:
    """The fit and held-out datasets without the readings the calibration set aside."""
    return (kept_datasets(list(datasets), result.rejected, "fit"),
            kept_datasets(list(validation), result.rejected, "validation"))


def _with_effects(result: CalibrationResult, robot, datasets, validation,
                  folder: Path | None) -> dict[str, float] | None:
    """RMS [m] of the model with effects, read back from ``folder`` when given."""
    if result.recommended != "final" or not result.effects:
        return None
    if folder is None or not (folder / EFFECTS_FILE).is_file():
        out = {"fit": result.fit.rms_final}
        if result.validation is not None:
            out["validation"] = result.validation.rms_final
        return out
    model = load_effects(folder, robot)
    values = {name: value for name, (value, _) in result.mounted.items()}
    start = 0
    for effect in model.effects:
        names = effect.parameter_names()
        values.update(zip(names, map(float, model.values[start:start + len(names)])))
        start += len(names)
    out = {}
    for role, data in (("fit", datasets), ("validation", validation)):
        if data:
            problem, x = evaluate(model.robot, list(data), model.effects, values) \
                if role == "fit" else held_out(model.robot, list(data), model.effects, values,
                                               anchors=datasets)
            out[role] = problem.rms(x)
    return out


TAKEN_UP = 0.5  # effects that leave under this share of the geometric fit's RMS count


def _effects_count(result: CalibrationResult) -> bool:
    """Whether what the identified effects move counts against robot_calibrated.yaml: when
    they are recommended, or when they take up most of what the geometry leaves on the
    fit data (its RMS falls below ``TAKEN_UP`` of the geometric fit's), whatever held-out
    data say: such effects are in the robot, and held-out data that favour the geometry
    then come from other loads or another robot. Effects recommended against that explain
    little (a few per cent) are not counted: the held-out data say they are not there."""
    if not result.effects:
        return False
    if result.recommended == "final":
        return True
    return bool(result.fit.rms_final < TAKEN_UP * result.fit.rms_geometric)


def _effect_model(result: CalibrationResult, names: list[str]):
    """The model with effects and its instrument point [m] (flange frame) when what the
    effects move counts (``_effects_count``), ``(None, None)`` otherwise: a controller
    runs geometry alone, so robot_calibrated.yaml misses it."""
    if not _effects_count(result) or len(names) != 3:
        return None, None
    from .projection import effect_model

    final_robot = result.robot_nominal.with_parameters(
        np.array([p.estimate for p in result.parameters], dtype=float))
    values = {name: value for name, (value, _) in result.mounted.items()}
    if not all(n in values for n in names):
        return None, None
    return effect_model(result, final_robot), [values[n] for n in names]


def _nominal(delivery, names: list[str]):
    """The nominal robot and its instrument point [m] as the file gives it, or None."""
    try:
        candidate = delivery.candidate("nominal")
    except KeyError:
        return None
    if len(names) != 3:
        return candidate.robot, [0.0, 0.0, 0.0]
    if not all(n in candidate.mounted for n in names):
        return None
    return candidate.robot, [candidate.mounted[n] for n in names]


def _effects_left_out(result: CalibrationResult, robot) -> float:
    """RMS distance [m] between the delivered geometry and the model with effects at the
    fit readings, when what the effects move counts (``_effects_count``) and a controller
    runs geometry alone."""
    if not _effects_count(result):
        return 0.0
    from ..model.kinematics import Kinematics
    from .projection import model_targets

    final_robot = result.robot_nominal.with_parameters(
        np.array([p.estimate for p in result.parameters], dtype=float))
    targets = model_targets(result, final_robot)
    if targets is None:
        return 0.0
    Q, T_target = targets
    T = Kinematics(robot).tool_poses(Q)
    return float(np.sqrt(np.mean(np.sum((T[:, :3, 3] - T_target[:, :3, 3]) ** 2, axis=1))))


@on_one_blas_thread
def write(result: CalibrationResult, datasets: Sequence, validation: Sequence, out: Path,
          report: ReportOptions = ReportOptions(), *, verb: str = "calibrate") -> JobOutcome:
    """Step 3: stage every file, measure the delivered ones as written, move into place
    (the folder's marker names ``verb``)."""
    with atomic_directory(out, verb=verb) as staging:
        for name in report.keep:
            if (out / name).is_file() and not (out / name).is_symlink():
                shutil.copy2(out / name, staging / name)
        save_robot(result.robot_calibrated, staging / ROBOT_FILE)
        save_effects(result, staging)
        with stage("figures from the written files"):
            result = measured(result, datasets, validation, staging / ROBOT_FILE, staging)
        (staging / "result.json").write_text(json.dumps(_clean(result.to_json()), indent=2)
                                             + "\n")
        write_errors_csv(result, staging)
        write_posterior(result, staging)
        if report.report:
            from ..report import write_report

            with stage("report"):
                release_freed()  # the calibration's freed memory, before the figures
                write_report(result, staging / "report.html", pdf=report.pdf,
                             info=report.info, templates=report.templates)
        written = tuple(sorted(p.name for p in staging.iterdir()))
    return JobOutcome(result, out, written)


def _profiled(datasets, validation, options: JobOptions) -> CalibrationResult:
    """The calibration restricted to ``options.profile``'s parameters, carrying what the
    unrestricted calibration of the same data reaches (``results.ProfileCost``)."""
    profile = str(options.profile)
    if options.parameters is not None:
        raise ArgumentError(f"a profile ({profile!r}) chooses the parameters itself; give "
                            "one of profile and parameters", argument="parameters")
    allowed = profile_parameters(profile, datasets[0].robot)
    free = _calibrate(datasets, validation, **options.calibrate_options())
    restricted = _calibrate(datasets, validation, parameters=allowed,
                            **options.calibrate_options())
    held = tuple(n for n in free.identifiability.identifiable
                 if n in free.robot_nominal.parameters() and n not in allowed)
    cost = ProfileCost(profile, allowed, held, free.fit, free.validation)
    return replace(restricted, profile=cost)
