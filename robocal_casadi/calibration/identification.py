"""Geometric calibration: from datasets to a ``CalibrationResult``.

``calibrate`` runs the whole job:

1. the nominal fit: the nominal robot with only the placement unknowns fitted
   (``rms_nominal``);
2. identifiability at that point (``identifiability.analyse``);
3. the geometric fit of every identifiable robot and mounted parameter, jointly with the
   placements (``rms_geometric``);
4. diagnosis of what the residual still holds (``diagnosis``), when asked; where the
   physical effects leave a structured residual (``unexplained``), a learned map of the
   tool position over the joints it follows, kept only when the folds confirm it
   (``learned``), the physical effects it may cover judged again beside it (``covered``);
5. validation on held-out datasets: robot, effects and mounted instrument from the
   calibration, placements fitted again.
"""

from __future__ import annotations

import difflib
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from ..common.checks import choice, count, positive
from ..common.fields import cut
from ..common.progress import reports_stages, stage
from ..effects.base import Effect
from ..errors import ArgumentError, InputError, SolverError
from ..instruments.datasets import DatasetBase, dataset_rows
from ..model.robot import Robot
from ..results import (
    DOMINATED_SHARE,
    CalibrationResult,
    DatasetResiduals,
    EffectFinding,
    Identifiability,
    ParameterEstimate,
    PriorSummary,
    RejectedReading,
    RmsSummary,
    SphereEstimate,
)
from . import covered, diagnosis, learned, outliers, remainder, unexplained
from .degeneracy import check_dataset, check_finite
from .evaluation import evaluate, models_for, refit_placement  # noqa: F401 (re-exported)
from .identifiability import EXACT_TOLERANCE, PRACTICAL_TOLERANCE, analyse
from .population_prior import PopulationPrior, PriorUse, judge, prior_for
from .prior import (
    SIGMA_ITERATIONS,
    SIGMA_SETTLED,
    Posterior,
    Prior,
    PriorProblem,
    copy_weights,
    duplicate_rows,
    posterior,
    settled_decrease,
    tolerance_of,
)
from .problem import Problem, StationFrames
from .selection import Selection, select_by_condition
from .solver import METHODS, Loss, Method, Solution, solve
from .start_state import settle_start

__all__ = ["Problem", "analyse_identifiability", "calibrate", "solve", "models_for"]


def consistent_problem(problem: Problem, x: np.ndarray) -> tuple[Problem, np.ndarray]:
    """The problem on data made consistent with ``x`` (see ``consistent_dataset``)."""
    p = x[problem.slices["robot"]]
    datasets, changed = [], False
    for model in problem.models:
        mounted = x[problem.mounted_indices(model)]
        placement = x[problem.placement_indices(model)]
        replaced = model.consistent_dataset(problem.kinematics, p, mounted, placement)
        changed |= replaced is not None
        datasets.append(replaced if replaced is not None else model.dataset)
    if not changed:
        return problem, x
    labels = [m.label for m in problem.models]
    models = [type(m)(d, label) for m, d, label in zip(problem.models, datasets, labels)]
    consistent = Problem(problem.robot, models, problem.effects, kinematics=problem.kinematics,
                         start=_values(problem, x))
    out = consistent.initial()
    out[consistent.mask("placement")] = x[problem.mask("placement")]
    return consistent, out


def analyse_identifiability(problem: Problem, x: np.ndarray,
                            candidates: Sequence[str] | None = None,
                            tolerance: float = PRACTICAL_TOLERANCE) -> Identifiability:
    """Identifiability of ``candidates`` (default: robot, effect and mounted unknowns) at ``x``.

    Judged on the Jacobian of data made consistent with ``x`` (``consistent_problem``).
    """
    problem, x = consistent_problem(problem, x)
    names = problem.unknowns.names
    if candidates is None:
        mask = problem.mask("robot", "effects", "mounted")
        candidate_index = [int(i) for i in np.flatnonzero(mask)]
    else:
        candidate_index = [problem.unknowns.index(n) for n in candidates]
    placement = [int(i) for i in np.flatnonzero(problem.mask("placement"))]
    invisible = "; ".join(sorted({getattr(m, "invisible_reason", "no effect on these data")
                                  for m in problem.models}))
    absorbed = "; ".join(sorted({getattr(m, "absorbed_reason", "absorbed by the placement")
                                 for m in problem.models}))
    with stage("identifiability"):
        jacobian = problem.jacobian(x)
        check_finite(problem.models, problem.residual(x), jacobian, "the fitted placement")
        return analyse(jacobian, names, candidate_index, placement,
                       invisible_reason=invisible, absorbed_reason=absorbed,
                       tolerance=tolerance)


def find_unexplained(problem: Problem, x: np.ndarray, free: np.ndarray):
    """The structured residual ``problem`` leaves at ``x``, or None (see ``unexplained``)."""
    with stage("unexplained test"):
        return unexplained.find(problem, x, free)


def _datasets(value, argument: str) -> list:
    """``value`` as a list of loaded datasets (a path or a single dataset is refused)."""
    if isinstance(value, (str, Path)) or not isinstance(value, (list, tuple)):
        hint = " (load it with load_dataset and pass a list)" if isinstance(
            value, (str, Path, DatasetBase)) else ""
        raise ArgumentError(f"expected a list of datasets, got a {type(value).__name__}{hint}",
                            argument=argument)
    wrong = [type(d).__name__ for d in value if not isinstance(d, DatasetBase)]
    if wrong:
        raise ArgumentError(f"expected datasets from load_dataset, got {', '.join(wrong[:3])}",
                            argument=argument)
    return list(value)


def _check_same_robot(datasets: Sequence) -> None:
    first = datasets[0]
    for dataset in datasets[1:]:
        if dataset.robot_path != first.robot_path and dataset.robot != first.robot:
            raise InputError(f"names robot file {dataset.robot_path}, but {first.path.name} names "
                             f"{first.robot_path}: datasets calibrated together must share one "
                             f"robot", file=dataset.path, where="robot")


def _free_mask(problem: Problem, identifiability: Identifiability) -> np.ndarray:
    free = problem.mask("placement")
    free[problem.unknowns.indices(identifiability.identifiable)] = True
    return free


def _residuals(problem: Problem, x_nominal, x_geometric, x_final) -> list[DatasetResiduals]:
    out = []
    stages = [(problem, x) for x in (x_nominal, x_geometric, x_final)]
    errors = [problem.errors(x) for x in (x_nominal, x_geometric, x_final)]
    parts = _components(stages)
    for k, model in enumerate(problem.models):
        dataset = model.dataset
        out.append(DatasetResiduals(
            label=model.label, kind=dataset.kind, errors_nominal=errors[0][k],
            errors_geometric=errors[1][k], errors_final=errors[2][k], rows=model.error_rows(),
            joints=dataset.joints, extras=dict(dataset.extras),
            payload_com=dataset.payload_com, components=parts[k], terms=model.error_terms(),
            frame=model.component_frame, lines=dataset.lines))
    return out


def _components(stages) -> list[dict[str, np.ndarray]]:
    """Per dataset, the signed error parts (N x 3) [m] under nominal, geometric, final."""
    out: list[dict[str, np.ndarray]] = []
    for name, (problem, x) in zip(("nominal", "geometric", "final"), stages):
        pieces = problem.split(problem.residual(x))
        for k, (model, r) in enumerate(zip(problem.models, pieces)):
            if len(out) <= k:
                out.append({})
            out[k][name] = model.error_components(r)
    return out


def _rms(errors: Sequence[np.ndarray]) -> float:
    flat = np.concatenate([np.asarray(e) for e in errors]) if errors else np.zeros(0)
    return float(np.sqrt(np.mean(flat**2))) if flat.size else float("nan")


def _values(problem: Problem, x: np.ndarray) -> dict[str, float]:
    keep = problem.mask("robot", "effects", "mounted")
    return {problem.unknowns.names[i]: float(x[i]) for i in np.flatnonzero(keep)}


Rule = Literal["prior", "fraction"]
RULES: tuple[Rule, ...] = get_args(Rule)
CalibrationLoss = Literal["robust", "linear", "huber"]
CALIBRATION_LOSSES: tuple[CalibrationLoss, ...] = get_args(CalibrationLoss)


@dataclass(frozen=True)
class NominalFit:
    """The nominal robot with only the placement unknowns fitted, and what the data identify.

    ``datasets`` are the data the calibration runs on (fewer units than given when
    ``selection`` dropped some); ``problem`` is built on them.
    """

    datasets: tuple[DatasetBase, ...]
    problem: Problem
    solution: Solution
    identifiability: Identifiability
    selection: Selection | None
    candidates: tuple[str, ...] | None = None  # the unknowns that may be fitted (None: all)


@dataclass(frozen=True)
class GeometricFit:
    """The geometric calibration: robot and mounted parameters jointly with the placements.

    ``prior`` is the tolerance prior it was weighed against (None under the ``fraction``
    rule), ``dominated`` the parameters whose estimate owes more to it than to the data,
    ``distinct`` the mask of residual entries from distinct readings (``duplicate_rows``).
    """

    identifiability: Identifiability
    solution: Solution
    prior: Prior | None
    dominated: frozenset[str]
    distinct: np.ndarray
    notes: tuple[str, ...]
    use: PriorUse | None = None  # which prior was used, and whether the robot belongs


@dataclass(frozen=True)
class DiagnosedFit:
    """The model after diagnosis: ``problem`` with the effects it added and their solution."""

    problem: Problem
    solution: Solution
    added: tuple[EffectFinding, ...]
    tested: tuple[diagnosis.CandidateTest, ...] = ()


@dataclass(frozen=True)
class Validation:
    """Held-out data under each model (see ``_validate``); empty when none were given."""

    summary: RmsSummary | None = None  # over the readings kept
    residuals: tuple[DatasetResiduals, ...] = ()
    spheres: tuple[SphereEstimate, ...] = ()
    all: RmsSummary | None = None  # over every reading, those set aside included
    rejected: tuple[RejectedReading, ...] = ()
    # the held-out problems under the geometric and the final model with their solutions
    # (placements fitted again), for what is measured on them afterwards
    fits: tuple[tuple[Problem, np.ndarray], ...] = field(default=(), repr=False,
                                                         compare=False)


@reports_stages(default=False)
def calibrate(datasets: Sequence, validation: Sequence = (), *, effects: Sequence[Effect] = (),
              diagnose: bool = True, method: Method = "lm", loss: CalibrationLoss = "robust",
              select_growth: float | None = None, max_iterations: int = 200,
              progress: bool = False, rule: Rule = "prior",
              parameters: Sequence[str] | None = None,
              fleet_prior: PopulationPrior | None = None) -> CalibrationResult:
    """Calibrate the robot shared by ``datasets``; see the module docstring.

    ``effects`` are declared effects identified from the start; ``diagnose`` lets the
    diagnosis add more. ``loss="robust"`` (default) first sets aside the units of data
    with gross errors (``outliers``: listed in ``result.rejected``), then runs everything
    below on the units kept by least squares; held-out data get the same treatment, their
    statistics given over all readings and over those kept. ``"linear"`` keeps every
    reading; ``"huber"`` keeps every reading and down-weights large residuals in the
    fits. ``method``, the fits' loss and ``max_iterations`` go to ``solver.solve``;
    a geometric fit that has not converged within ``max_iterations`` is a ``SolverError``. With
    ``select_growth`` (e.g. 0.05), units of data that grow the condition number by more
    than that fraction are dropped first, as in the published cross-bar method
    (``selection``, docs/methods.md#cross-bar-calibration); what was dropped is in
    ``result.selection``.

    ``rule`` decides which parameters the data estimate. ``"prior"`` (default): every
    parameter that is not exactly undeterminable (no effect, absorbed by the placement,
    an exact combination of others), by maximum a posteriori against the robot's
    tolerances (``prior``); the parameters the prior dominates are flagged. ``"fraction"``:
    every parameter with at least ``PRACTICAL_TOLERANCE`` of its effect its own, by least
    squares, the rest held at nominal. Either way the least-squares fit of the second kind
    runs first: it checks that the data determine what they must and sets the noise level.
    Standard errors count repeated identical readings once (a warning on stderr says so).

    Arguments are checked at the door (``ArgumentError``, a ``ValueError``): ``method`` one
    of ``solver.METHODS``, ``loss`` one of ``CALIBRATION_LOSSES`` (a misspelt name gets
    the closest valid one as a hint), datasets loaded by ``load_dataset``, ``effects``
    ``Effect`` objects, ``max_iterations`` a whole number >= 1, ``select_growth`` None or
    a number >= 0, ``rule`` one of ``RULES``. ``parameters`` (robot parameter names)
    restricts the robot parameters that may be fitted, e.g. to a controller's set
    (``profiles``); the others are held at nominal. Default: all of them. ``progress``
    shows each stage (fits, identifiability, diagnosis rounds and refits, the
    unexplained test) with its elapsed time on standard error when it is a terminal.
    ``fleet_prior`` (rule ``"prior"`` only): a population prior learned from robots of
    this model (``population_prior``), used in place of the tolerances of the robot
    parameters it covers unless this robot's data contradict it beyond their noise, in
    which case the tolerance prior is used and ``result.prior.use`` says so.
    """
    request = _Request.checked(datasets, validation, effects, method=method, loss=loss,
                               rule=rule, max_iterations=max_iterations,
                               select_growth=select_growth, parameters=parameters,
                               fleet_prior=fleet_prior)
    nominal, rejected, geometric, final = _fits(request, diagnose)
    structure = find_unexplained(final.problem, final.solution.x, final.solution.free)
    if diagnose:
        final = _learned(final, structure, geometric.prior, len(nominal.problem.effects),
                         method=request.method, loss=request.fit_loss)
    return _result(request, nominal, geometric, final, structure, rejected)


@dataclass(frozen=True)
class _Request:
    """``calibrate``'s arguments as checked at the door (see ``calibrate``), with the
    robot the datasets share."""

    robot: Robot
    datasets: list[DatasetBase]
    validation: list[DatasetBase]
    effects: Sequence[Effect]
    method: Method
    loss: CalibrationLoss
    rule: Rule
    max_iterations: int
    select_growth: float | None
    parameters: tuple[str, ...] | None
    fleet_prior: PopulationPrior | None = None

    @property
    def robust(self) -> bool:
        """Gross errors are set aside before the least-squares fits."""
        return self.loss == "robust"

    @property
    def fit_loss(self) -> Loss:
        """The loss of the fits themselves."""
        return "linear" if self.loss == "robust" else self.loss

    @classmethod
    def checked(cls, datasets: Sequence, validation: Sequence, effects: Sequence[Effect], *,
                method: Method, loss: CalibrationLoss, rule: Rule, max_iterations: int,
                select_growth: float | None, parameters: Sequence[str] | None,
                fleet_prior: PopulationPrior | None = None) -> _Request:
        """The arguments checked, in canonical form (``ArgumentError``, ``InputError``)."""
        method = choice(method, METHODS, "method")
        rule = choice(rule, RULES, "rule")
        loss = choice(loss, CALIBRATION_LOSSES, "loss")
        max_iterations = count(max_iterations, "max_iterations")
        if select_growth is not None:
            select_growth = positive(select_growth, "select_growth", allow_zero=True)
        datasets = _datasets(datasets, "datasets")
        validation = _datasets(validation, "validation")
        _check_effects(effects)
        if not datasets:
            raise InputError("no dataset given")
        _check_same_robot(datasets + validation)
        for dataset in datasets + validation:
            check_dataset(dataset)
        robot = datasets[0].robot
        names = None if parameters is None else parameter_names(
            parameters, robot.parameters().names, "parameters")
        if fleet_prior is not None:
            if rule != "prior":
                raise ArgumentError("a fleet prior needs rule 'prior', got 'fraction'",
                                    argument="fleet_prior")
            fleet_prior.check_robot(robot, fleet_prior.path)
        return cls(robot, datasets, validation, effects, method, loss, rule, max_iterations,
                   select_growth, names, fleet_prior)


def _fits(request: _Request, diagnose: bool
          ) -> tuple[NominalFit, tuple[RejectedReading, ...], GeometricFit, DiagnosedFit]:
    """Stages 1-4 up to the effects diagnosis adds: the nominal fit (on the units kept
    when robust), the geometric fit and the diagnosed model, and the units set aside."""
    method, fit_loss, max_iterations = request.method, request.fit_loss, request.max_iterations
    nominal = _nominal_fit(request.robot, request.datasets, request.effects,
                           request.select_growth, request.parameters, method=method,
                           loss=fit_loss)
    rejected: tuple[RejectedReading, ...] = ()
    screened_from = nominal.datasets
    deferred = False  # too many set aside before the diagnosis: judged after it instead
    if request.robust:
        nominal, rejected, deferred = _screened(nominal, request.effects, method=method,
                                                max_iterations=max_iterations,
                                                defer=diagnose)
    for attempt in range(2):
        short: InputError | None = None
        try:
            identifiability, least_squares = _geometric_fit(
                nominal, method=method, loss=fit_loss, max_iterations=max_iterations)
        except InputError as error:
            # Data too few for least squares alone: a population prior, which knows what
            # robots of the model are like, may still determine the rest (what a fleet
            # prior is for); the tolerance prior is not trusted to.
            if request.fleet_prior is None or request.rule != "prior":
                raise
            identifiability, least_squares, short = nominal.identifiability, None, error
        geometric = _prior_fit(nominal, identifiability, least_squares, request.rule,
                               method=method, loss=fit_loss, max_iterations=max_iterations,
                               fleet=request.fleet_prior)
        if short is not None and not (geometric.use is not None and geometric.use.belongs):
            raise InputError(f"{short.what}; the fleet prior, which could have made up "
                             f"for it, does not hold for this robot", file=short.file,
                             where=short.where)
        if short is not None and diagnose:
            # Residuals fewer than the unknowns: any effect would fit them exactly, and the
            # held-out rules would have nothing left to judge it on.
            note = ("effects not sought: the readings are fewer than the unknowns, and the "
                    "fleet prior, not the data, determines the rest")
            print(f"note: {note}", file=sys.stderr)
            geometric = replace(geometric, notes=geometric.notes + (note,))
        final = _diagnose(nominal.problem, geometric, request.validation,
                          diagnose and short is None, method=method, loss=fit_loss)
        # Effects found change what the residual holds: readings set aside before they
        # were known are judged again under the final model (once).
        if not request.robust or not (final.added or deferred) or attempt:
            break
        revised = _rescreened(screened_from, final, rejected, method=method,
                              max_iterations=max_iterations)
        if revised is None:
            break
        kept, rejected = revised
        nominal = _refitted(nominal, kept, request.effects, method=method)
    return nominal, rejected, geometric, final


def _result(request: _Request, nominal: NominalFit, geometric: GeometricFit,
            final: DiagnosedFit, structure: unexplained.Unexplained | None,
            rejected: tuple[RejectedReading, ...]) -> CalibrationResult:
    """Stage 5 and the result: the errors under each model, the held-out data, standard
    errors, the recommended model and every estimate. The calibrated robot takes the
    recommended model's geometry."""
    problem, robot = nominal.problem, request.robot
    x_nominal_final = _embed(problem, nominal.solution.x, final.problem)
    x_geometric_final = _embed(problem, geometric.solution.x, final.problem)
    residuals = _residuals(final.problem, x_nominal_final, x_geometric_final, final.solution.x)
    fit = RmsSummary(problem.rms(nominal.solution.x), problem.rms(geometric.solution.x),
                     final.problem.rms(final.solution.x))
    held_out = Validation()
    if request.validation:
        held_out = _validate(robot, request.validation, problem, (nominal.solution.x,
                                                                   geometric.solution.x),
                             final.problem, final.solution.x, robust=request.robust,
                             identifiable=nominal.identifiability.identifiable)
    std, prior_summary, notes = _standard_errors(final, geometric, request.rule)
    recommended, recommendation = recommend(fit, held_out.summary, bool(final.added))
    chosen = final.solution if recommended == "final" else geometric.solution
    ours = _final_estimates(final, std)
    left = _remainder(request, final, held_out,
                      (problem, geometric.solution) if recommended == "geometric" else None)
    covariance_names, covariance = _geometric_covariance(problem, geometric.solution)
    return CalibrationResult(
        datasets=tuple(d.path.name for d in nominal.datasets), robot_nominal=robot,
        robot_calibrated=robot.with_parameters(chosen.x[problem.slices["robot"]]),
        parameters=tuple(_estimates(problem, geometric.identifiability, final.solution.x, std)),
        identifiability=geometric.identifiability,
        condition_number=geometric.identifiability.condition_number, effects=ours.effects,
        fit=fit, validation=held_out.summary, residuals=tuple(residuals),
        validation_residuals=held_out.residuals, mounted=ours.mounted,
        mounted_quantities=ours.mounted_quantities, placement=ours.placement,
        solver=_solver_summary(request.method, request.loss, problem, nominal.solution,
                               geometric.solution, final.solution),
        effect_models=tuple(final.problem.effects),
        effect_values=final.solution.x[final.problem.slices["effects"]].copy(),
        diagnosis=tuple(final.tested),
        selection={} if nominal.selection is None else dict(nominal.selection.dropped),
        parameters_geometric=tuple(_estimates(problem, geometric.identifiability,
                                              geometric.solution.x, geometric.solution.std)),
        unexplained=structure, recommended=recommended, recommendation=recommendation,
        prior=prior_summary,
        spheres=_spheres(final.problem, final.solution.x, std, "fit") + held_out.spheres,
        notes=geometric.notes + notes,
        mounted_geometric=_mounted_values(problem, geometric.solution.x),
        covariance_names=covariance_names, covariance=covariance,
        rejected=rejected + held_out.rejected, validation_all=held_out.all, remainder=left)


def _remainder(request: _Request, final: DiagnosedFit, held_out: Validation,
               geometric: tuple[Problem, Solution] | None = None
               ) -> remainder.Remainder | None:
    """What the recommended model leaves beside the instruments' noise: on the validation
    data when given, else held out of the fit data (a learned map's own folds when one was
    added). ``geometric`` (problem and solution): the geometric model, where the held-out
    data recommended it over the final one; what remains is then what it leaves."""
    maps = [f for f in final.added if "cv_rms_after" in f.evidence]
    cv = float(maps[-1].evidence["cv_rms_after"]) if maps else None
    with stage("remainder"):
        if held_out.summary is not None:
            problem, solution = geometric if geometric is not None else \
                (final.problem, final.solution)
            rms = held_out.summary.rms_geometric if geometric is not None else \
                held_out.summary.rms_final
            held = held_out.fits[0 if geometric is not None else 1]
            return remainder.measure(problem, solution.x, solution.free,
                                     validation_models=models_for(request.validation,
                                                                  "validation:"),
                                     validation_rms=rms,
                                     estimation=_estimation(solution, problem, *held))
        return remainder.measure(final.problem, final.solution.x, final.solution.free,
                                 cv_rms=cv)


def _estimation(solution: Solution, problem: Problem, held_out: Problem,
                x_held: np.ndarray) -> float | None:
    """What the uncertainty of ``solution``'s estimates (in ``problem``) gives on the
    validation data [m] (``remainder.estimation_rms``), on the held-out problem validation
    built, its placements fitted again (``x_held``)."""
    covariance = solution.covariance
    if covariance is None or covariance.shape != (int(solution.free.sum()),) * 2:
        return None
    return remainder.estimation_rms(problem, solution.x, solution.free, covariance,
                                    held_out, x_held)


@dataclass(frozen=True)
class _FinalEstimates:
    """What the final model estimates beyond the robot: the mounted instrument (value and
    standard error [SI]) with each one's quantity, the placements [SI], and the effects
    found with their standard errors."""

    mounted: dict[str, tuple[float, float | None]]
    mounted_quantities: dict[str, str]
    placement: dict[str, float]
    effects: tuple[EffectFinding, ...]


def _final_estimates(final: DiagnosedFit, std: np.ndarray) -> _FinalEstimates:
    """The final model's mounted, placement and effect estimates; ``std`` [SI] the
    standard error of every unknown of ``final.problem`` (NaN where not estimated)."""
    problem, x = final.problem, final.solution.x
    names = problem.unknowns.names
    mounted = {names[i]: (float(x[i]), _finite(std[i]))
               for i in range(problem.slices["mounted"].start, problem.slices["mounted"].stop)}
    placement = {names[i]: float(x[i]) for i in range(problem.slices["placement"].start,
                                                      problem.slices["placement"].stop)}
    effects = tuple(replace(f, std={n: _finite(std[problem.unknowns.index(n)])
                                    for n in f.parameters}) for f in final.added)
    return _FinalEstimates(mounted, {name: problem.unknowns.quantity(name) for name in mounted},
                           placement, effects)


def _mounted_values(problem: Problem, x: np.ndarray) -> dict[str, float]:
    """The mounted instrument's values [SI] in ``x`` by name."""
    names = problem.unknowns.names
    return {names[i]: float(x[i])
            for i in range(problem.slices["mounted"].start, problem.slices["mounted"].stop)}


def _geometric_covariance(problem: Problem, geometric: Solution
                          ) -> tuple[tuple[str, ...], np.ndarray]:
    """The names of the geometric fit's free robot and mounted parameters and their
    posterior covariance [SI], in that order (what the delivery starts from)."""
    kept_slices = (problem.slices["robot"], problem.slices["mounted"])
    robot_free = [i for i in np.flatnonzero(geometric.free)
                  if any(part.start <= i < part.stop for part in kept_slices)]
    position = {int(i): k for k, i in enumerate(np.flatnonzero(geometric.free))}
    kept = [position[int(i)] for i in robot_free]
    covariance = (np.asarray(geometric.covariance)[np.ix_(kept, kept)]
                  if np.size(geometric.covariance) else np.zeros((0, 0)))
    return tuple(problem.unknowns.names[i] for i in robot_free), covariance


def _solver_summary(method: Method, loss: CalibrationLoss, problem: Problem, nominal: Solution,
                    geometric: Solution, final: Solution) -> dict[str, str | int | float]:
    """How the solver ran: the final fit's iterations and status, the time of the
    nominal and geometric fits [s], the residual entries and free unknowns of the
    geometric fit."""
    return {"method": method, "loss": loss, "iterations": final.iterations,
            "status": final.status, "seconds": geometric.seconds + nominal.seconds,
            "residuals": problem.size, "free_unknowns": int(geometric.free.sum())}


def parameter_names(value, valid: Sequence[str], argument: str) -> tuple[str, ...]:
    """``value`` (one name, or a list of names) as names from ``valid``; an unknown name
    or a value that is not text is an ``ArgumentError`` naming it (with the closest valid
    name as a hint). One string is one name, never a set of characters."""
    names = [value] if isinstance(value, str) else value
    if not isinstance(names, (list, tuple, set, frozenset)):
        raise ArgumentError(f"expected a parameter name or a list of names, got a "
                            f"{type(value).__name__}", argument=argument)
    out = []
    for name in names:
        if not isinstance(name, str):
            raise ArgumentError(f"expected parameter names (text), got {cut(name)}",
                                argument=argument)
        if name not in valid:
            close = difflib.get_close_matches(name, list(valid), n=1, cutoff=0.6)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ArgumentError(f"unknown parameter {cut(name)}{hint}; the robot's parameters "
                                f"are {cut(list(valid), 120)}", argument=argument)
        out.append(name)
    if not out:
        raise ArgumentError("no parameter names given: nothing could be fitted (give None "
                            "for all of them)", argument=argument)
    return tuple(dict.fromkeys(out))


def _check_effects(effects: Sequence) -> None:
    if not isinstance(effects, (list, tuple)):
        raise ArgumentError(f"expected a list of Effect objects, got a {type(effects).__name__}",
                            argument="effects")
    wrong = sorted({type(e).__name__ for e in effects if not isinstance(e, Effect)})
    if wrong:
        raise ArgumentError("expected Effect objects (robocal_casadi.effects), got "
                            + ", ".join(wrong), argument="effects")


def _nominal_fit(robot: Robot, datasets: list[DatasetBase], effects: Sequence[Effect],
                 select_growth: float | None, parameters: Sequence[str] | None, *,
                 method: Method, loss: Loss) -> NominalFit:
    """Stage 1-2: the nominal fit and identifiability there, after selection if asked."""
    problem = Problem(robot, models_for(datasets), effects)
    candidates = None
    if parameters is not None:
        allowed = set(parameters)
        robot_names = set(problem.kinematics.registry.names)
        open_ = problem.mask("robot", "effects", "mounted")
        candidates = tuple(n for i, n in enumerate(problem.unknowns.names)
                           if open_[i] and (n not in robot_names or n in allowed))
    with stage("nominal fit"):
        nominal = solve(problem, problem.initial(), problem.mask("placement"), method=method,
                        loss=loss)
    identifiability = analyse_identifiability(problem, nominal.x, candidates)
    selection = None
    if select_growth is not None and identifiability.identifiable:
        selection = select_by_condition(problem, nominal.x, identifiability.identifiable,
                                        growth=select_growth)
        if any(selection.dropped.values()):
            datasets = [m.subset(np.asarray(selection.kept[m.label], dtype=int))
                        for m in problem.models]
            problem = Problem(robot, models_for(datasets), effects, kinematics=problem.kinematics)
            nominal = solve(problem, problem.initial(), problem.mask("placement"),
                            method=method, loss=loss)
            identifiability = analyse_identifiability(problem, nominal.x, candidates)
    if not identifiability.identifiable:
        raise InputError("the data identify no robot parameter (too few or degenerate rows)",
                         file=datasets[0].path)
    return NominalFit(tuple(datasets), problem, nominal, identifiability, selection, candidates)


def _screened(nominal: NominalFit, effects: Sequence[Effect], *, method: Method,
              max_iterations: int, defer: bool
              ) -> tuple[NominalFit, tuple[RejectedReading, ...], bool]:
    """The nominal fit again on the units ``outliers.screen`` keeps, those it set aside,
    and whether the judgement was deferred.

    Screened with the unknowns the data determine at nominal, from a robust start; every
    later stage (identifiability, fits, diagnosis, noise level) sees the kept units only.
    When more than ``outliers.MAX_SHARE`` of a dataset would go and ``defer`` (a diagnosis
    follows), nothing is set aside yet: so many readings far off the geometric model say
    as much about what the model lacks as about the data, and they are judged under the
    model the diagnosis ends with (``_rescreened``), where too many still refuse the data.
    """
    problem = nominal.problem
    free = _free_mask(problem, nominal.identifiability)
    screening = outliers.screen(problem, nominal.solution.x, free, method=method,
                                max_iterations=max_iterations)
    if not screening.rejected:
        return nominal, (), False
    if defer and outliers.exceeds_share(problem, screening):
        return nominal, (), True
    outliers.check_share(problem, screening)
    rejected = outliers.rejected_readings(problem, screening)
    datasets = [dataset_rows(m.dataset, keep)
                for m, keep in zip(problem.models, screening.kept_rows(problem))]
    return _refitted(nominal, datasets, effects, method=method), rejected, False


def _refitted(nominal: NominalFit, datasets: Sequence[DatasetBase], effects: Sequence[Effect],
              *, method: Method) -> NominalFit:
    """``nominal`` again on ``datasets`` (the nominal fit and identifiability there)."""
    problem = Problem(nominal.problem.robot, models_for(datasets), effects,
                      kinematics=nominal.problem.kinematics)
    solution = solve(problem, problem.initial(), problem.mask("placement"), method=method)
    identifiability = analyse_identifiability(problem, solution.x, nominal.candidates)
    if not identifiability.identifiable:
        raise InputError("the readings kept identify no robot parameter", file=datasets[0].path)
    return replace(nominal, datasets=tuple(datasets), problem=problem, solution=solution,
                   identifiability=identifiability)


def _rescreened(datasets: Sequence[DatasetBase], final: DiagnosedFit,
                rejected: tuple[RejectedReading, ...], *, method: Method, max_iterations: int
                ) -> tuple[list, tuple[RejectedReading, ...]] | None:
    """The units of ``datasets`` (all of them) judged under the final model, starting from
    those ``rejected``; None when the same are set aside, else the kept data and them."""
    full = Problem(final.problem.robot, models_for(datasets), final.problem.effects,
                   start=_values(final.problem, final.solution.x),
                   kinematics=final.problem.kinematics)
    units = outliers.units_of(full)
    lines = {(e.path, line) for e in rejected for line in e.lines}
    before = tuple(k for k, unit in enumerate(units) if all(
        (str(full.models[unit.model].dataset.path), full.models[unit.model].dataset.line(row))
        in lines for row in unit.rows))
    weights = outliers.weights_of(full, units, before)
    x = outliers.refit(full, full.initial(), full.mask("placement"), weights, method=method)
    free = full.mask("placement")
    names = [final.problem.unknowns.names[i] for i in np.flatnonzero(final.solution.free)]
    free[full.unknowns.indices([n for n in names if n in full.unknowns])] = True
    screening = outliers.screen(full, x, free, method=method, max_iterations=max_iterations,
                                robust_start=False, rejected=before)
    if set(screening.rejected) == set(before):
        return None
    outliers.check_share(full, screening)
    kept = [dataset_rows(m.dataset, keep)
            for m, keep in zip(full.models, screening.kept_rows(full))]
    return kept, outliers.rejected_readings(full, screening)


def _geometric_fit(nominal: NominalFit, *, method: Method, loss: Loss,
                   max_iterations: int) -> tuple[Identifiability, Solution]:
    """Stage 3, by least squares: the parameters with a fair share of their effect their own.

    Refuses (``InputError``, ``SolverError``) data too few for them, estimates the data
    leave undetermined, and a fit that does not converge.
    """
    problem, identifiability = nominal.problem, nominal.identifiability
    path = nominal.datasets[0].path
    free = _free_mask(problem, identifiability)
    rows_needed = int(free.sum())
    # Repeated readings (a copied placement or reading) add rows but no information:
    # the count that must exceed the unknowns is that of distinct readings' residuals.
    distinct, repeated, units_of_data = duplicate_rows(problem)
    size = int(distinct.sum())
    if size <= rows_needed:
        copies = (f" ({repeated} of {units_of_data} placements or readings repeat an earlier "
                  f"one exactly and count once)") if repeated else ""
        raise InputError(f"{size} residuals of distinct readings cannot identify {rows_needed} "
                         f"unknowns{copies}; add data", file=path)
    with stage("identification"):
        geometric = solve(problem, nominal.solution.x, free, method=method, loss=loss,
                          max_iterations=max_iterations)
    # Dependencies seen at the nominal geometry can be artefacts of its symmetry (a target
    # exactly on the flange axis makes d5 and alpha5 act alike); judge again at the
    # estimate and, where more parameters turn out identifiable, solve once more.
    revised = analyse_identifiability(problem, geometric.x, nominal.candidates)
    if set(revised.identifiable) > set(identifiability.identifiable):
        identifiability = revised
        free = _free_mask(problem, identifiability)
        with stage("identification"):
            geometric = solve(problem, geometric.x, free, method=method, loss=loss,
                              max_iterations=max_iterations)
    # A fit wandering along a flat valley neither converges nor means anything: say why.
    _check_determined(problem, geometric, path)
    if geometric.status != "converged":
        rms = float(np.sqrt(np.mean(geometric.residual**2)))
        raise SolverError(
            f"{path.name}: the geometric calibration ({method}) did not converge: "
            f"{geometric.status} after {geometric.iterations} iterations, residual RMS "
            f"{rms:.4g} m; check the data for outliers (--loss huber) or allow more "
            f"iterations (--max-iterations)",
            stats={"iterations": geometric.iterations, "status": geometric.status})
    return identifiability, geometric


def _prior_fit(nominal: NominalFit, identifiability: Identifiability,
               least_squares: Solution | None, rule: Rule, *, method: Method, loss: Loss,
               max_iterations: int, fleet: PopulationPrior | None = None) -> GeometricFit:
    """Stage 3 under ``rule``: ``"prior"`` refits by maximum a posteriori; both flag
    repeated readings and the parameters the prior dominates. ``least_squares`` is None
    where the data were too few for it (only with a fleet prior): the fit then starts from
    the nominal fit and weighs the prior against the instruments' own noise."""
    # The least-squares fit, on the parameters with a fair share of their own, also gives
    # the noise level the prior is weighed against.
    problem = nominal.problem
    distinct, repeated, units_of_data = duplicate_rows(problem)
    notes = (_warn_duplicates(repeated, units_of_data),) if repeated else ()
    geometric, prior, use = least_squares, None, None
    if least_squares is None:
        noise, start = _instrument_sigma(problem), nominal.solution.x
    else:
        noise = posterior(problem.jacobian(least_squares.x, least_squares.free),
                          problem.residual(least_squares.x),
                          np.flatnonzero(least_squares.free), None, rows=distinct).sigma
        start = least_squares.x
    if rule == "prior":
        determined = identifiability
        identifiability, geometric, prior, use = _map_geometric(
            problem, nominal.solution.x, start, noise, distinct, method=method, loss=loss,
            max_iterations=max_iterations, candidates=nominal.candidates, fleet=fleet,
            noise_known=least_squares is None)
        # The condition number describes the data: that of the parameters with a fair share
        # of their effect their own (the weak ones lean on the prior, not on the data).
        identifiability = replace(identifiability,
                                  condition_number=determined.condition_number)
        if geometric.status != "converged":
            raise SolverError(
                f"{nominal.datasets[0].path.name}: the maximum a posteriori calibration "
                f"({method}) did not converge: {geometric.status} after "
                f"{geometric.iterations} iterations",
                stats={"iterations": geometric.iterations, "status": geometric.status})
    assert geometric is not None  # least squares is skipped only under the prior rule
    dominated = frozenset(_dominated(problem, geometric, prior, distinct))
    return GeometricFit(identifiability, geometric, prior, dominated, distinct, notes, use)


def _instrument_sigma(problem: Problem) -> float:
    """The RMS [m] of the instruments' own noise over ``problem``'s residual entries
    (declared ``instrument_noise`` or each instrument's typical value)."""
    noise = np.concatenate([m.entry_noise() for m in problem.models])
    noise = noise[noise > 0]
    return float(np.sqrt(np.mean(noise**2))) if noise.size else float("nan")


def _diagnose(problem: Problem, geometric: GeometricFit, validation: Sequence[DatasetBase],
              diagnose: bool, *, method: Method, loss: Loss) -> DiagnosedFit:
    """Stage 4: the effects diagnosis adds to the geometric model (none unless asked)."""
    if not diagnose:
        return DiagnosedFit(problem, geometric.solution, ())
    # An effect must also be usable on the held-out data: columns they all carry.
    available = None
    if validation:
        available = set.intersection(*(set(d.extras) for d in validation))
    # What the prior dominates stays where the prior put it while effects are sought:
    # an unweighted refit would let it wander along the direction the data lack.
    searched = _holding(geometric.solution,
                        problem.unknowns.indices(sorted(geometric.dominated)))
    outcome = diagnosis.run(problem, searched, geometric.identifiability, method=method,
                            loss=loss, available_columns=available)
    final = geometric.solution if outcome.solution is searched else outcome.solution
    return DiagnosedFit(outcome.problem, final, outcome.added, outcome.tested)


def _learned(final: DiagnosedFit, structure, prior: Prior | None, declared: int, *,
             method: Method, loss: Loss) -> DiagnosedFit:
    """Stage 4, last: the learned map over the joints the unexplained ``structure``
    follows, added when the folds confirm it (``learned``); else ``final`` unchanged.
    The physical effects added on those joints (``final.problem.effects`` after the first
    ``declared``) are judged again beside the map, and those it covers go (``covered``).
    The geometry is refitted with the map in under the fit's own ``prior`` (None: plain
    least squares)."""
    if structure is None:
        return final
    with stage("learned map"):
        outcome = learned.learn(final.problem, final.solution.x, structure.variables)
    if outcome is None or outcome.effect is None:
        return final
    effect, diagnosed = outcome.effect, final
    with stage("physical effects beside the learned map"):
        beside = covered.without_stand_ins(
            final.problem, final.solution, declared, effect.joints, final.added,
            max((t.round for t in final.tested), default=0) + 1, method=method, loss=loss)
    if beside.removed:
        with stage("learned map"):
            again = learned.learn(beside.problem, beside.solution.x, structure.variables)
        if again is not None and again.effect is not None:
            final = replace(final, problem=beside.problem, solution=beside.solution,
                            added=beside.added, tested=final.tested + beside.removed)
            outcome, effect = again, again.effect
    problem, solution = learned.with_map(final.problem, final.solution, effect,
                                         prior=prior, method=method, loss=loss)
    before, after = final.problem.rms(final.solution.x), problem.rms(solution.x)
    if not after < before:
        return diagnosed  # no map: what it would have covered stays
    finding = learned.finding(outcome, (before, after), problem.robot.units)
    return replace(final, problem=problem, solution=solution, added=final.added + (finding,))


def _standard_errors(final: DiagnosedFit, geometric: GeometricFit,
                     rule: Rule) -> tuple[np.ndarray, PriorSummary, tuple[str, ...]]:
    """Standard errors [SI] of every unknown at the final estimate (NaN where not estimated).

    From distinct readings only, with the prior on every parameter it weighs (held ones
    included). Also what the prior did, and a note when no noise level can be estimated.
    """
    problem, solution = final.problem, final.solution
    free = solution.free.copy()
    free[problem.unknowns.indices(sorted(geometric.dominated))] = True
    prior = None if geometric.prior is None else geometric.prior.placed_in(problem)
    distinct, _, _ = duplicate_rows(problem)
    statistics = posterior(problem.jacobian(solution.x, free), problem.residual(solution.x),
                           np.flatnonzero(free), prior, rows=distinct,
                           certified=problem.certified_entries())
    std = np.full(len(problem.unknowns), np.nan)
    std[free] = statistics.std
    notes: tuple[str, ...] = ()
    if not np.isfinite(statistics.sigma):
        notes = ("the distinct readings leave no degree of freedom to estimate the noise: "
                 "no standard errors",)
    return std, _prior_summary(problem, prior, statistics, rule, geometric.use), notes


def _finite(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def _warn_duplicates(repeated: int, units: int) -> str:
    """One line on stderr (and the note for result.json) about repeated readings."""
    note = (f"{repeated} of {units} units of data (placements or readings) repeat an earlier "
            f"one exactly; standard errors count each distinct reading once")
    print(f"warning: {note}", file=sys.stderr)
    return note


def _dominated(problem: Problem, solution: Solution, prior: Prior | None, distinct) -> set[str]:
    """Names of the parameters whose estimate the prior dominates (data share < 1/2)."""
    if prior is None or not len(prior.index):
        return set()
    statistics = posterior(problem.jacobian(solution.x, solution.free), solution.residual,
                           np.flatnonzero(solution.free), prior, rows=distinct)
    return {name for name, share in zip(prior.names, statistics.share)
            if np.isfinite(share) and share < DOMINATED_SHARE}


def _holding(solution: Solution, held: np.ndarray) -> Solution:
    """``solution`` with the unknowns ``held`` (indices) no longer free."""
    if not len(held):
        return solution
    free = solution.free.copy()
    free[held] = False
    keep = free[solution.free]
    return replace(solution, free=free, covariance=solution.covariance[np.ix_(keep, keep)])


def _prior_summary(problem: Problem, prior: Prior | None, statistics: Posterior,
                   rule: str, use: PriorUse | None = None) -> PriorSummary:
    """What the prior did: tolerances (the prior's standard deviations) and the data's
    share per parameter, noise level, centres, and which prior it was."""
    if prior is None:
        return PriorSummary(rule=rule, noise=statistics.sigma)
    share = dict(zip(prior.names, (float(s) for s in statistics.share)))
    return PriorSummary(rule=rule, noise=statistics.sigma,
                        tolerance=dict(zip(prior.names, map(float, prior.tolerance))),
                        data_share=share,
                        quantities={n: problem.unknowns.quantity(n) for n in prior.names},
                        centre=dict(zip(prior.names, map(float, prior.centre))), use=use)


def _map_solve(problem: Problem, x: np.ndarray, free: np.ndarray, prior: Prior, distinct,
               *, method: Method, loss: Loss, max_iterations: int, noise_known: bool = False):
    """MAP estimate over ``x[free]``; the noise level re-estimated until it settles
    (``noise_known``: kept at ``prior.sigma``, where the data are too few to tell it).

    The fit ends when it has settled (``prior.settled_decrease``).
    """
    decrease = settled_decrease(problem)
    for _ in range(1 if noise_known else SIGMA_ITERATIONS):
        with stage("identification with the prior"):
            solution = solve(PriorProblem(problem, prior, copy_weights(problem)), x, free,
                             method=method, loss=loss, max_iterations=max_iterations,
                             decrease=decrease)
        x = solution.x
        r = problem.residual(x)
        statistics = posterior(problem.jacobian(x, free), r, np.flatnonzero(free), prior,
                               rows=distinct, certified=problem.certified_entries(),
                               noise_known=noise_known)
        settled = abs(statistics.sigma / prior.sigma - 1.0) < SIGMA_SETTLED
        if noise_known or not np.isfinite(statistics.sigma) or settled:
            break
        prior = prior.with_sigma(statistics.sigma)
    covariance = np.nan_to_num(statistics.covariance, nan=0.0)
    return replace(solution, residual=r, cost=0.5 * float(r @ r), covariance=covariance), prior


def _map_geometric(problem: Problem, x_nominal: np.ndarray, x_start: np.ndarray, sigma: float,
                   distinct, *, method: Method, loss: Loss, max_iterations: int,
                   candidates: Sequence[str] | None = None,
                   fleet: PopulationPrior | None = None, noise_known: bool = False):
    """Identifiability with exact dependencies only, and the MAP fit of the rest
    (``candidates``: the unknowns that may be fitted, default all).

    Exact dependencies are judged at a generic point near nominal (``generic_point``), not
    at the nominal geometry itself: a nominal design is often symmetric (a target on the
    flange axis, an offset of exactly zero) and there parameters act alike that a real
    robot, off its drawing by its tolerances, tells apart. What the data barely see there
    is left to the prior, not held at nominal.

    With a ``fleet`` population prior, the fit is made under it first; when this robot's
    data contradict it (``population_prior.judge``), again under the tolerance prior.
    Returns the identifiability, the solution, the prior used and a ``PriorUse``.
    """
    if not np.isfinite(sigma) or sigma <= 0:
        sigma = max(problem.rms(x_start), 1e-12)
    identifiability = analyse_identifiability(problem, generic_point(problem, x_nominal),
                                              candidates, tolerance=EXACT_TOLERANCE)
    free = _free_mask(problem, identifiability)
    tolerance_prior = prior_for(problem, free, sigma, None)
    offered, member = None, None
    if fleet is not None:
        widened = _with_population(identifiability, fleet, candidates)
        fleet_free = _free_mask(problem, widened)
        population = prior_for(problem, fleet_free, sigma, fleet)
        start = np.array(x_start, float)
        if noise_known:  # no least-squares start: the population's robot is the best guess
            start[population.index] = population.centre
        solution, prior = _map_solve(problem, start, fleet_free, population,
                                     distinct, method=method, loss=loss,
                                     max_iterations=max_iterations, noise_known=noise_known)
        position = {int(i): k for k, i in enumerate(np.flatnonzero(fleet_free))}
        where = [position[int(i)] for i in prior.index]
        member = judge(prior, solution.covariance[np.ix_(where, where)], solution.x, fleet,
                       problem.robot.name)
        offered = str(fleet.path) if fleet.path is not None else "fleet prior"
        if member.belongs:
            return widened, solution, prior, PriorUse(
                offered, offered, True, member, prior.names, prior.centre, prior.covariance)
    solution, prior = _map_solve(problem, x_start, free, tolerance_prior,
                                 distinct, method=method, loss=loss,
                                 max_iterations=max_iterations, noise_known=noise_known)
    use = PriorUse("tolerance", offered, None if fleet is None else False, member,
                   prior.names, prior.centre, prior.covariance)
    return identifiability, solution, prior, use


def _with_population(identifiability: Identifiability, fleet: PopulationPrior,
                     candidates: Sequence[str] | None) -> Identifiability:
    """``identifiability`` widened by the parameters the population's calibrations fitted:
    with few readings the rank of their Jacobian says how many readings there are, not
    what the instrument sees, and holding those parameters at the drawing would contradict
    the population that knows them (the prior determines what the data do not)."""
    known = [n for n in fleet.fitted() if n in identifiability.unidentifiable
             and (candidates is None or n in candidates)]
    if not known:
        return identifiability
    return replace(identifiability,
                   identifiable=identifiability.identifiable + tuple(known),
                   unidentifiable={n: why for n, why in identifiability.unidentifiable.items()
                                   if n not in known})


GENERIC_SCALE = 0.1  # generic point: robot and mounted parameters off nominal by this x tolerance
GENERIC_SEED = 20261122  # fixed, so that a calibration is repeatable


def generic_point(problem: Problem, x: np.ndarray) -> np.ndarray:
    """``x`` with every robot and mounted parameter moved off nominal by a fixed random
    fraction (``GENERIC_SCALE``, one standard deviation) of its tolerance [SI].

    Exact (structural) dependencies hold at every geometry and survive the move; those
    owed to the symmetry of the nominal drawing do not.
    """
    moved = np.array(x, float)
    rng = np.random.default_rng(GENERIC_SEED)
    for i in np.flatnonzero(problem.mask("robot", "mounted")):
        name = problem.unknowns.names[i]
        tolerance = tolerance_of(name, problem.unknowns.quantity(name), problem.robot)
        step = rng.normal()  # drawn for every parameter: the move does not depend on the file
        if tolerance is not None:
            moved[i] += GENERIC_SCALE * tolerance * step
    return moved


def _estimates(problem: Problem, identifiability: Identifiability, x: np.ndarray,
               std: np.ndarray) -> list[ParameterEstimate]:
    """One row per geometric parameter of ``problem``'s robot at ``x`` (SI)."""
    nominal_vector = problem.kinematics.nominal
    rows = []
    for i, name in enumerate(problem.kinematics.registry.names):
        identified = name in identifiability.identifiable
        rows.append(ParameterEstimate(
            name=name, quantity=problem.kinematics.registry.quantities[i],
            nominal=float(nominal_vector[i]), estimate=float(x[i]),
            std=_finite(std[i]) if identified else None, identifiable=identified,
            reason=identifiability.unidentifiable.get(name)))
    return rows


def recommend(fit: RmsSummary, validation: RmsSummary | None,
              added: bool) -> tuple[str, str]:
    """``("final" | "geometric", why)``: which model the user should take.

    The held-out data decide: when they show the model with the added effects worse
    than the geometric one, the geometric model is recommended (and written as the
    calibrated robot), whatever the fit data say.
    """
    if not added:
        return "final", "diagnosis added no effect: the final model is the geometric one"
    if validation is None:
        return "final", ("the added effects passed the cross-validation of the fit data; "
                         "no held-out data were given to confirm them")
    if validation.rms_final > validation.rms_geometric:
        return "geometric", ("the held-out data show the model with effects worse than the "
                             "geometric one; they decide over the cross-validation of the fit "
                             "data, having taken no part in choosing or fitting the model")
    return "final", "the held-out data confirm the added effects"


UNDETERMINED_STD = {"length": 0.1, "angle": 0.1, "none": 0.1}  # [m], [rad], [1]


def _check_determined(problem: Problem, solution: Solution, path) -> None:
    """Refuse a fit whose robot or mounted estimates the data leave undetermined.

    Identifiability is judged on the linearised problem; with barely enough data the
    least-squares minimum can still lie anywhere along a nearly flat valley (a probe
    offset of metres fitting 12 bar placements to the noise). A standard error beyond
    ``UNDETERMINED_STD`` (0.1 m, 0.1 rad) means the data do not fix the parameter at all.
    """
    std = solution.std
    names = problem.unknowns.names
    keep = problem.mask("robot", "effects", "mounted") & solution.free
    loose = [(names[i], float(std[i]), problem.unknowns.quantity(names[i]))
             for i in np.flatnonzero(keep)
             if not std[i] <= UNDETERMINED_STD.get(problem.unknowns.quantity(names[i]), 0.1)]
    if loose:
        units = {"length": "m", "angle": "rad"}
        listed = ", ".join(f"{n} (std {v:.3g} {units.get(q, '')})".replace(" )", ")")
                           for n, v, q in loose[:6])
        more = f" and {len(loose) - 6} more" if len(loose) > 6 else ""
        raise InputError(f"the data do not determine {listed}{more}: {problem.size} "
                         f"residuals for {int(solution.free.sum())} unknowns leave them free; "
                         f"add data (more placements or readings, more varied orientations)",
                         file=path)


def _embed(source: Problem, x: np.ndarray, target: Problem) -> np.ndarray:
    """``x`` of ``source`` placed into ``target``'s layout by name (missing effects zero)."""
    if target is source:
        return x
    out = np.zeros(len(target.unknowns))
    for i, name in enumerate(source.unknowns.names):
        if name in target.unknowns:
            out[target.unknowns.index(name)] = x[i]
    return out


def _validate(robot: Robot, validation: Sequence[DatasetBase], problem: Problem,
              x_fits: tuple[np.ndarray, np.ndarray], final_problem: Problem,
              x_final: np.ndarray, *, robust: bool = False,
              identifiable: Sequence[str] = ()) -> Validation:
    """Stage 5: the held-out data under the nominal, geometric and final models
    (``x_fits``: the nominal and geometric fits in ``problem``).

    Robot, effects and mounted instrument come from the calibration; the placements are
    fitted again on the held-out data, except those of an instrument station the fit data
    share, which each model keeps as its fit left them (``StationFrames``). ``robust``:
    the units that are gross errors are set aside, the placements of every model fitted
    on the rest; the statistics are given
    over the readings kept (``summary``) and over all of them (``all``). Gross errors are
    judged as in the fit (``outliers.screen``, the ``identifiable`` parameters free with
    the placements): a reading the calibrated model merely predicts less well than the
    others is the model's error, not the reading's, and is kept.
    """
    stages = []
    # the side of the play each joint starts the held-out tables on is theirs, like the
    # placement (start_state)
    settled = settle_start(robot, validation, final_problem.effects,
                           _values(final_problem, x_final), problem.kinematics)
    x_nominal, x_geometric = x_fits
    for stage_problem, x, nominal in ((problem, x_nominal, True), (problem, x_geometric, False),
                                      (final_problem, x_final, False)):
        values = {} if nominal else _values(stage_problem, x)
        with stage("validation"):
            val_problem, x_val = evaluate(robot, settled, stage_problem.effects, values,
                                          kinematics=problem.kinematics,
                                          label_prefix="validation:",
                                          frames=StationFrames.of(stage_problem, x))
        stages.append((val_problem, x_val))
    rejected: tuple[RejectedReading, ...] = ()
    kept = [np.ones(len(m.error_rows()), dtype=bool) for m in stages[-1][0].models]
    if robust:
        last, x_last = stages[-1]
        screening = outliers.screen(last, x_last, _screened_unknowns(last, identifiable))
        if screening.rejected:
            rejected = outliers.rejected_readings(last, screening, role="validation")
            kept = screening.kept_errors(last)
            stages = [(p, outliers.refit(p, x, p.free_placement(), screening.weights))
                      for p, x in stages]
    errors = [p.errors(x) for p, x in stages]
    every = RmsSummary(*(_rms(e) for e in errors))
    summary = RmsSummary(*(_rms([e[m] for e, m in zip(stage, kept)]) for stage in errors))
    residuals = []
    parts = _components(stages)
    for k, model in enumerate(stages[-1][0].models):
        dataset = model.dataset
        residuals.append(DatasetResiduals(
            label=model.label, kind=dataset.kind, errors_nominal=errors[0][k],
            errors_geometric=errors[1][k], errors_final=errors[2][k], rows=model.error_rows(),
            joints=dataset.joints, extras=dict(validation[k].extras),
            payload_com=dataset.payload_com, components=parts[k], terms=model.error_terms(),
            frame=model.component_frame, lines=dataset.lines,
            placement_frame=stages[-1][0].placement_frame(model)))
    validation_problem, x_validation = stages[-1]
    return Validation(summary, tuple(residuals),
                      _spheres(validation_problem, x_validation, None, "validation"),
                      all=every, rejected=rejected, fits=tuple(stages[1:]))


def _screened_unknowns(problem: Problem, identifiable: Sequence[str]) -> np.ndarray:
    """The placements and the ``identifiable`` parameters, when the data are enough for
    them (twice as many residual entries); else the placements alone."""
    free = problem.free_placement()
    wider = free.copy()
    wider[problem.unknowns.indices([n for n in identifiable if n in problem.unknowns])] = True
    return wider if problem.size >= 2 * int(wider.sum()) else free


def _spheres(problem: Problem, x: np.ndarray, std: np.ndarray | None, role: str) -> tuple:
    """Sphere centre [m] (base frame, with standard errors) and radius [m] per sphere dataset."""
    out = []
    for model in problem.models:
        if not model.sphere:
            continue
        index = problem.placement_indices(model)
        centre_std = None if std is None else [_finite(std[i]) for i in index]
        x_centre, y_centre, z_centre = (float(x[i]) for i in index)
        out.append(SphereEstimate(label=model.label, role=role,
                                  centre=(x_centre, y_centre, z_centre),
                                  centre_std=None if centre_std is None else tuple(centre_std),
                                  radius=float(model.dataset.radius)))
    return tuple(out)
