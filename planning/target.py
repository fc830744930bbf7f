"""How many placements or readings a target accuracy needs, before measuring.

For a plan of ``n`` placements or readings (designed by ``design.design_plan`` for the
index ``tool``) with identification Jacobian ``J`` [m per SI unit] over the robot and
mounted parameters (placement unknowns projected out) and reading noise ``sigma`` [m],
the parameter error of a robot calibrated with a Gaussian prior of precision ``P``
[1/SI^2] (the tolerance prior, ``calibration.prior``, or a fleet's population prior,
``calibration.population_prior``) has the covariance

    Sigma = (J^T J / sigma^2 + P)^-1.

Parameters neither identifiable on the plan nor covered by a prior are held at their
nominal value, as the planner does, and left out. The square of one robot's RMS tool
error over the workspace (its best rigid motion removed, ``accuracy.tool_weights``
``W``) is then ``sum_i lambda_i z_i^2`` with ``lambda_i`` the eigenvalues of
``Sigma W`` and ``z`` standard normal: the weighted sum of chi-squares the calibrate
job's band uses (``job.accuracy.rms_band``, its seeded draws ``results.BAND_SEED``).
Its ``QUANTILE`` quantile
is the figure a count must bring to the target: nine robots in ten calibrated on such a
plan do at least that well.

The search doubles the count from the least the planner accepts until a plan reaches
the target, then bisects between the last count that did not and the first that did;
every count tried is designed afresh (the curve printed is those counts' figures).

With a fleet prior the least count least squares needs is not a floor: the calibration
weighs the readings against the population and fits data fewer than its unknowns. When
the least plan the planner designs already reaches the target, smaller ones are made from
it by backward elimination (Bayesian design, Chaloner and Verdinelli 1995, "Bayesian
experimental design: a review", Statistical Science 10(3), section 2): one placement or
reading at a time, the one whose removal raises the predicted figure under the fleet prior
least, as long as the rest still reach the target. Those counts' tolerance-prior figure is
left out: the tolerance prior does not let such data be calibrated.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, replace
from typing import TextIO

import numpy as np

from robocal_casadi.calibration.prior import tolerance_of
from robocal_casadi.common.progress import Progress
from robocal_casadi.instruments.datasets import Dataset
from robocal_casadi.results import BAND_DRAWS as DRAWS
from robocal_casadi.results import BAND_SEED as SEED

from .accuracy import tool_weights
from .design import DEFAULT_INDEX, Plan, TooFew, design_plan
from .information import _project_shared
from .order import order_candidates
from .rows import RowModel
from .runnable import runnable_setup
from .setup import setup_from_dataset

LIMIT = 128  # the largest count the search designs
QUANTILE = 0.9  # share of robots the target is to hold for


@dataclass(frozen=True)
class Trial:
    """One count tried: ``rms`` [m] the ``QUANTILE`` quantile of one robot's predicted RMS
    over the workspace, ``mean_rms`` [m] the root of its mean square (inf: the planner
    could not fill the count); with a fleet prior, ``tolerance_rms`` [m] the quantile the
    tolerance prior would give on the same plan (inf: too few for it to calibrate; None
    without a fleet prior)."""

    count: int
    rms: float
    mean_rms: float
    tolerance_rms: float | None = None


@dataclass(frozen=True)
class TargetSearch:
    """The outcome: ``target`` [m], the counts ``trials`` tried (by count), ``count`` the
    fewest that reached the target (None: none up to ``limit``), its ``plan``, the
    ``prior`` used (``"tolerance"`` or the fleet prior's file)."""

    target: float
    limit: int
    trials: tuple[Trial, ...]
    count: int | None
    plan: Plan | None
    prior: str

    @property
    def best(self) -> Trial:
        return min(self.trials, key=lambda t: t.rms)

    def curve(self, scale: float, unit: str) -> str:
        """The curve as lines, figures divided by ``scale`` [m per ``unit``]."""
        lines = [f"count -> predicted work-cell RMS for {round(100 * QUANTILE)}% of robots "
                 f"[{unit}] (root mean square over robots) with the {self.prior} prior"
                 + ("; with the tolerance prior" if self.prior != "tolerance" else "") + ":"]
        for t in self.trials:
            mark = "  <- fewest reaching the target" if t.count == self.count else ""
            figure = ("too few for the planner" if not math.isfinite(t.rms) else
                      f"{t.rms / scale:.4g} ({t.mean_rms / scale:.4g})"
                      + ("" if t.tolerance_rms is None else
                         "; tolerance prior: too few to calibrate"
                         if not math.isfinite(t.tolerance_rms) else
                         f"; tolerance prior {t.tolerance_rms / scale:.4g}"))
            lines.append(f"  {t.count:5d}  {figure}{mark}")
        return "\n".join(lines)


class Predictor:
    """The ``QUANTILE`` RMS of plans for one set-up and prior (module docstring)."""

    def __init__(self, dataset: Dataset, fleet=None, seed: int = 0):
        setup, kinematics, workspace = runnable_setup(setup_from_dataset(dataset))
        self.setup = setup
        self.workspace = workspace
        self.rows = RowModel(setup, kinematics)
        names = self.rows.parameters
        self.weights = tool_weights(setup, workspace, names, np.random.default_rng(seed))
        self.prior = prior_precision(names, kinematics.registry, setup.robot, fleet)
        self.tolerance = (None if fleet is None else
                          prior_precision(names, kinematics.registry, setup.robot))

    def trial(self, plan: Plan) -> Trial:
        """The figures of ``plan`` under the prior (and the tolerance prior beside a fleet's)."""
        rms, mean = self.rms(plan, *self.prior)
        beside = None if self.tolerance is None else self.rms(plan, *self.tolerance)[0]
        return Trial(len(plan.candidates), rms, mean, beside)

    def rms(self, plan: Plan, covered: np.ndarray, precision: np.ndarray
            ) -> tuple[float, float]:
        """``(quantile, root mean square)`` [m] of one robot's RMS calibrated on ``plan``
        with a prior of ``precision`` over the ``covered`` parameters."""
        return self.rms_of([b.X for b in self.rows.blocks(list(plan.candidates))],
                           plan.identifiable, covered, precision)

    def rms_of(self, blocks: list[np.ndarray], identifiable: tuple[str, ...],
               covered: np.ndarray, precision: np.ndarray) -> tuple[float, float]:
        """``rms`` of the design whose candidates' Jacobian rows are ``blocks`` (robot and
        mounted columns, then the placement unknowns), fitting ``identifiable``."""
        names = self.rows.parameters
        n = len(names)
        X = np.vstack(blocks)
        J = _project_shared(X[:, :n], X[:, n:])
        keep = covered | np.isin(np.array(names), np.array(identifiable))
        A = J.T @ J / self.setup.noise**2 + precision
        A = A[np.ix_(keep, keep)]
        d = 1.0 / np.sqrt(np.diag(A))  # scaled: lengths and angles side by side
        covariance = d[:, None] * np.linalg.inv(d[:, None] * A * d[None, :]) * d[None, :]
        root = np.linalg.cholesky(0.5 * (covariance + covariance.T))
        W = self.weights[np.ix_(keep, keep)]
        lam = np.clip(np.linalg.eigvalsh(root.T @ W @ root), 0.0, None)[::-1]
        # the band's draws (results.BAND_SEED), every weight kept, largest first: two priors
        # over the same parameters meet the same z, so a tighter prior (smaller weights,
        # one by one) never shows a larger quantile through sampling alone
        z = np.random.default_rng(SEED).standard_normal((DRAWS, len(lam)))
        high = float(np.quantile(np.sqrt(z**2 @ lam), QUANTILE))
        return high, float(np.sqrt(lam.sum()))


def prior_precision(names: tuple[str, ...], registry, robot, fleet=None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """``(covered, P)``: which of ``names`` (robot then mounted) carry a prior and its
    precision [1/SI^2] over all of them (zero rows and columns where none): the tolerance
    prior, with the fleet's population covariance in its place on the robot parameters
    ``fleet`` covers (as ``population_prior.prior_for`` builds the calibration's)."""
    robot_names = set(registry.names)
    covariance = np.zeros((len(names), len(names)))
    covered = np.zeros(len(names), bool)
    for k, name in enumerate(names):
        quantity = registry.quantity(name) if name in robot_names else (
            "length" if name[-1] in "xyz" else "direction")
        t = tolerance_of(name, quantity, robot)
        if t is not None:
            covariance[k, k], covered[k] = t**2, True
    if fleet is not None:
        mine = [k for k, n in enumerate(names) if n in fleet.names]
        theirs = [fleet.names.index(names[k]) for k in mine]
        covariance[np.ix_(mine, mine)] = fleet.covariance[np.ix_(theirs, theirs)]
        covered[mine] = True
    precision = np.zeros_like(covariance)
    index = np.flatnonzero(covered)
    precision[np.ix_(index, index)] = np.linalg.inv(covariance[np.ix_(index, index)])
    return covered, precision


def search(dataset: Dataset, target: float, *, fleet=None, limit: int | None = None,
           seed: int = 0, refine: bool = True, stream: TextIO | None = None) -> TargetSearch:
    """The fewest placements or readings predicted to reach ``target`` [m] for
    ``QUANTILE`` of robots (module docstring); ``stream`` for the progress line (default
    standard error, silent unless a terminal); ``limit`` the largest count designed
    (default ``LIMIT``)."""
    limit = LIMIT if limit is None else limit
    predictor = Predictor(dataset, fleet, seed)
    trials: dict[int, Trial] = {}
    plans: dict[int, Plan] = {}
    needed = 1  # the least count the planner last said it can fill
    with Progress("plan: target", total=None, stream=stream or sys.stderr) as progress:

        def reaches(count: int) -> bool | None:
            """None: too few for the planner."""
            progress.update(len(trials) + 1, f"designing a plan of {count}")
            try:
                plan = design_plan(dataset, count, DEFAULT_INDEX, seed=seed, refine=refine,
                                   quiet=True)
            except TooFew as error:
                trials[count] = Trial(count, math.inf, math.inf)
                if error.needed <= count:  # no plan found: ask for more
                    error.needed = count + 1
                nonlocal needed
                needed = error.needed
                return None
            plans[count] = plan
            trials[count] = predictor.trial(plan)
            return trials[count].rms <= target

        count, low, high = 1, 0, None
        while count <= limit:
            outcome = reaches(count)
            if outcome is None:
                low = count
                count = needed
                continue
            if outcome:
                high = count
                break
            low = count
            count = limit if count < limit < 2 * count else 2 * count
        if high is not None:
            while high - low > 1:
                middle = (low + high) // 2
                if reaches(middle):
                    high = middle
                else:
                    low = middle
        if fleet is not None and high is not None:
            high = _below_least_squares(trials, plans, high, predictor, target)
    ordered = tuple(trials[c] for c in sorted(trials))
    prior = "tolerance" if fleet is None else f"fleet ({fleet.path})"
    return TargetSearch(target, limit, ordered, high, plans.get(high) if high else None, prior)


def _below_least_squares(trials: dict[int, Trial], plans: dict[int, Plan], high: int,
                         predictor: Predictor, target: float) -> int:
    """Where the least plan the planner designs (``high``) reaches ``target`` [m] under a
    fleet prior, the smaller plans ``_fewer`` makes, entered in ``trials`` and ``plans``
    (the planner's "too few" below ``high`` no longer the last word); the fewest count
    reaching the target."""
    if any(c < high and math.isfinite(t.rms) for c, t in trials.items()):
        return high  # a smaller plan was designed and did not reach it
    for count in [c for c in trials if c < high]:
        del trials[count]
    for plan in _fewer(plans[high], predictor, target):
        count = len(plan.candidates)
        trials[count] = replace(predictor.trial(plan), tolerance_rms=math.inf)
        if trials[count].rms <= target:
            plans[count], high = plan, count
    return high


def _fewer(plan: Plan, predictor: Predictor, target: float) -> list[Plan]:
    """Plans of fewer placements or readings than ``plan`` (the least the planner designs),
    one fewer each, by backward elimination under the predictor's fleet prior (module
    docstring): every one that reaches ``target`` [m] and the first that does not."""
    blocks = [b.X for b in predictor.rows.blocks(list(plan.candidates))]
    chosen = list(range(len(blocks)))
    out = []
    while len(chosen) > 1:
        figures = [predictor.rms_of([blocks[i] for i in chosen if i != drop],
                                    plan.identifiable, *predictor.prior)[0]
                   for drop in chosen]
        best = int(np.argmin(figures))  # ties: the first in plan order goes
        chosen.pop(best)
        candidates, travel = order_candidates([plan.candidates[i] for i in chosen],
                                              predictor.workspace, keep_given=True)
        out.append(replace(
            plan, candidates=candidates, value=math.nan, random_values=np.zeros(0),
            singular_values=np.zeros(0), tool_error=math.nan, random_tool_errors=np.zeros(0),
            condition_all=math.nan, travel=travel, tool_error_bound=math.nan,
            random_conditions_all=np.zeros(0), least_squares_count=len(plan.candidates)))
        if not figures[best] <= target:
            break
    return out
