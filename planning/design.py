"""Designing measurement poses for a dataset's set-up: ``design_plan``.

1. draw a pool of feasible candidates (``candidates``),
2. compute each candidate's Jacobian rows at the nominal robot (``rows``),
3. find the identifiable parameters on the whole pool (``information``),
4. choose ``count`` candidates: exchanges for the chosen index from a greedy start and
   from random starts, the best kept (``selection``), then refine the chosen joints
   continuously (``refine``),
5. report the index of the plan beside the median of random feasible plans of the
   same size drawn from the same pool.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field

import numpy as np

from robocal_casadi.common.progress import Progress
from robocal_casadi.errors import ArgumentError, InputError
from robocal_casadi.instruments import instrument
from robocal_casadi.instruments.datasets import Dataset

from .accuracy import tool_error, tool_weights
from .approximate import optimal_approximate
from .candidates import Candidate, generate
from .compare import clearly_greater
from .indices import DEFAULT_INDEX, DESCRIPTIONS, canonical, index_value, scaling, score
from .information import EXACT_TOLERANCE, Information, exact_condition
from .order import Travel, order_candidates
from .refine import refine_plan
from .rows import RowModel
from .runnable import runnable_setup
from .selection import exchange, greedy, random_designs
from .setup import PlanSetup, setup_from_dataset

RANDOM_PLANS = 20
STARTS = 4  # exchange searches: one from the greedy design, the others from random ones
# the condition number is not smooth in the design (its extreme singular values swap
# places), so its exchange search stops in many more local optima: more starts
STARTS_CONDITION = 12
REFINE_ROUNDS = 3  # each round moves joints at most refine.STEP


class TooFew(InputError):
    """A count the planner cannot fill: fewer placements or readings than the identifiable
    parameters need (``needed``: the least count worth asking for)."""

    def __init__(self, message: str, needed: int, **where):
        super().__init__(message, **where)
        self.needed = needed


@dataclass(frozen=True)
class Plan:
    """A designed set of measurements and how good it is.

    ``candidates`` the chosen placements or readings; ``index`` (canonical name, e.g.
    ``O2``) and its ``value`` for the plan; ``random_values`` the same index for random
    feasible plans of the same size; ``singular_values`` of the plan's column-scaled
    identification Jacobian (scaled as the index asks, see ``indices``);
    ``identifiable`` the parameters it is computed over. ``tool_error`` [m] the
    predicted standard error of the tool position over the workspace at the set-up's
    reading noise (``accuracy``), ``random_tool_errors`` the same for the random plans;
    ``condition_all`` the condition number over every parameter not exactly
    unidentifiable; ``travel`` the joint moves between consecutive poses in run order;
    ``tool_error_bound`` [m] the least predicted tool error any plan of the same size
    chosen from the candidates could have (``approximate``; refinement may go below it);
    ``random_conditions_all`` the random plans' ``condition_all``.
    """

    setup: PlanSetup
    candidates: tuple[Candidate, ...]
    index: str
    value: float
    random_values: np.ndarray
    singular_values: np.ndarray
    identifiable: tuple[str, ...]
    pool_size: int
    swaps: int
    refined: bool = False
    tool_error: float = float("nan")
    random_tool_errors: np.ndarray = field(default_factory=lambda: np.zeros(0))
    condition_all: float = float("nan")
    travel: Travel | None = None
    tool_error_bound: float = float("nan")
    random_conditions_all: np.ndarray = field(default_factory=lambda: np.zeros(0))
    least_squares_count: int | None = None
    """Set on a plan of fewer placements or readings than least squares needs (this
    count), chosen for a fleet prior that determines the rest (``target``)."""

    @property
    def random_tool_median(self) -> float:
        """Median predicted tool-position error [m] of the random plans."""
        if not len(self.random_tool_errors):
            return float("nan")
        return float(np.median(self.random_tool_errors))

    @property
    def random_median(self) -> float:
        return _median(self.random_values)

    @property
    def joints(self) -> np.ndarray:
        """All rows' joint readings (R x dof) [rad or m]."""
        return np.vstack([c.joints for c in self.candidates])

    @property
    def poses(self) -> np.ndarray:
        """Placement id (1-based) of each row."""
        return np.concatenate([np.full(len(c.joints), k + 1)
                               for k, c in enumerate(self.candidates)])

    @property
    def points(self) -> tuple[str, ...]:
        return tuple(p for c in self.candidates for p in c.points)

    def __repr__(self) -> str:
        return (f"Plan({self.setup.kind}, {len(self.candidates)} of {self.pool_size} candidates, "
                f"{self.index} = {self.value:.6g} vs random median {self.random_median:.6g}, "
                f"{len(self.identifiable)} identifiable parameters)")

    def summary(self) -> str:
        what = self.setup.model.unit_name
        if self.least_squares_count is not None:
            return (f"planned {len(self.candidates)} {what} ({len(self.joints)} rows), fewer "
                    f"than the {self.least_squares_count} least squares needs for "
                    f"{len(self.identifiable)} identifiable parameters: the fleet prior "
                    f"determines the rest (calibrate with --prior); chosen from a plan of "
                    f"{self.least_squares_count} by the predicted work-cell RMS under that "
                    f"prior; without it these data cannot be calibrated"
                    + (f"\n{self.travel.summary()}" if self.travel is not None else ""))
        ratio = self.value / self.random_median if self.random_median else math.nan
        return (f"planned {len(self.candidates)} {what} ({len(self.joints)} rows) for "
                f"{len(self.identifiable)} identifiable parameters, chosen from "
                f"{self.pool_size} feasible candidates\n"
                f"{self.index} ({DESCRIPTIONS[self.index]}): plan {self.value:.6g}, random "
                f"feasible plans of the same size: median {self.random_median:.6g} "
                f"(ratio {ratio:.3g}, {len(self.random_values)} plans)\n"
                f"predicted tool-position error over the workspace at "
                f"{1e3 * self.setup.noise:.3g} mm reading noise: plan "
                f"{1e3 * self.tool_error:.4g} mm, random median "
                f"{1e3 * self.random_tool_median:.4g} mm; no choice among the candidates "
                f"can go below {1e3 * self.tool_error_bound:.4g} mm (refinement, which "
                f"leaves them, may)\n"
                f"condition number over every parameter not exactly unidentifiable: plan "
                f"{self.condition_all:.4g}, random median "
                f"{_median(self.random_conditions_all):.4g}"
                + (f"\n{self.travel.summary()}" if self.travel is not None else "")
                + (f"\n{self.warning}" if self.warning else ""))

    @property
    def warning(self) -> str:
        """A line when the plan is predicted to calibrate less accurately than the median
        random plan of its size ('' otherwise): an index other than ``tool`` can reward
        balance between parameters over information (a well-conditioned plan of poses
        that barely move the measured point)."""
        random = self.random_tool_median
        if not (np.isfinite(self.tool_error) and random > 0 and self.tool_error > random):
            return ""
        return (f"warning: this plan is predicted to place the tool "
                f"{self.tool_error / random:.3g} times less accurately than the median random "
                f"plan of its size; the index 'tool' plans for accuracy")


def _median(values: np.ndarray) -> float:
    return float(np.median(values)) if len(values) else float("nan")


def pool_size_for(count: int, kind: str) -> int:
    """How many feasible candidates to draw for a plan of ``count`` (the measurement
    model's ``pool_size``)."""
    least, per_count = instrument(kind).model.pool_size
    return max(least, per_count * count)


# long: the design reads as the method in one place: pool, start, exchange, refinement and the
# kept best, each step already a helper; splitting it would pass the same state around.
def design_plan(dataset: Dataset, count: int, index: str = DEFAULT_INDEX, *, seed: int = 0,
                pool: int | None = None, refine: bool = True, refine_rounds: int = REFINE_ROUNDS,
                quiet: bool = False) -> Plan:
    """Design ``count`` placements (touch kinds) or readings for ``dataset``'s set-up.

    ``index``: ``tool`` (predicted tool-position error, the default), ``cond`` (=
    ``O2``) or ``O1`` ... ``O5``; ``seed`` fixes the random search;
    ``pool`` the number of feasible candidates drawn (default ``pool_size_for``);
    ``refine`` runs up to ``refine_rounds`` continuous refinements; ``quiet`` silences
    the progress line.
    """
    index = canonical(index)
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ArgumentError(f"expected a whole number >= 1, got {count!r}", argument="count")
    setup, kinematics, workspace = runnable_setup(setup_from_dataset(dataset))
    # one stream draws the candidates, another the search's starts and the random plans:
    # how many draws finding the candidates took does not move the search's
    draws, rng = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    size = pool or pool_size_for(count, setup.kind)
    stream = io.StringIO() if quiet else None  # Progress stays silent on a non-terminal
    with Progress("plan: candidates", total=size, stream=stream) as progress:
        candidates = generate(setup, workspace, size, draws, progress)
    if len(candidates) < count:
        raise InputError(f"only {len(candidates)} feasible candidates found; ask for at most "
                         f"that many (--count {count})", file=setup.path)
    row_model = RowModel(setup, kinematics)
    weights = tool_weights(setup, workspace, row_model.parameters, np.random.default_rng(seed))
    # The condition index is judged over every parameter not exactly unidentifiable, the
    # measure the summary reports: a weak parameter left out of the search would come
    # back in the plan's condition number unchecked.
    info = Information(row_model.blocks(candidates), row_model.parameters, row_model.shared,
                       weights, tolerance=EXACT_TOLERANCE if index == "O2" else None)
    needed = math.ceil((info.m + info.shared) / info.rows_per_candidate())
    if count < needed:
        what = setup.model.unit_name
        raise TooFew(
            f"--count {count} is too few: {info.m} identifiable parameters"
            f"{f' and {info.shared} placement unknowns' if info.shared else ''} need at least "
            f"{needed} {what} of this kind", needed, file=setup.path)
    with Progress("plan: exchange, start", total=_starts(index), stream=stream) as progress:
        chosen, swaps = _best_exchange(info, len(candidates), count, index, rng, progress)
    chosen_candidates = tuple(candidates[i] for i in chosen)
    spectrum = info.spectrum(chosen, scaling(index))
    refined = False
    if refine:
        chosen_candidates, spectrum, refined = _refined(
            setup, workspace, row_model, info, chosen_candidates, spectrum, index, refine_rounds)
    value = index_value(index, spectrum)
    if not np.isfinite(value) or spectrum[-1] <= 1e-10 * spectrum[0]:
        raise TooFew(f"no plan of {count} found that identifies all {info.m} parameters; "
                     f"ask for more (--count)", count + 1, file=setup.path)
    random_values, random_tool, random_condition = _random_plans(
        setup, row_model, info, candidates, count, index, rng)
    blocks = row_model.blocks(list(chosen_candidates))
    predicted = tool_error(info.spectrum_of([info.restrict(b) for b in blocks], "tool"),
                           setup.noise)
    bound = optimal_approximate(info).tool_error_bound(count, setup.noise)
    ordered, travel = order_candidates(chosen_candidates, workspace)
    return Plan(setup, ordered, index, value, random_values, spectrum,
                info.identifiable_names, len(candidates), swaps, refined, predicted,
                random_tool, exact_condition(blocks, row_model.parameters, row_model.shared),
                travel, bound, random_condition)


def _starts(index: str) -> int:
    """How many exchange searches (a greedy start, then random ones): more for the
    condition number, whose landscape is rougher."""
    return STARTS_CONDITION if index == "O2" else STARTS


def _best_exchange(info: Information, pool: int, count: int, index: str,
                   rng: np.random.Generator, progress: Progress) -> tuple[list[int], int]:
    """``(chosen candidates, swaps)``: the best exchange search of a greedy start and
    random ones (more for the condition number, whose landscape is rougher)."""
    best: tuple[float, list[int], int] | None = None
    for start in range(_starts(index)):  # a greedy start, then random ones: keep the best
        if start == 0:
            initial = greedy(info, count, rng)
        else:
            initial = list(rng.choice(pool, size=count, replace=False))
        chosen, swaps = exchange(info, initial, index, progress=progress, start=start + 1)
        value = score(index, index_value(index, info.spectrum(chosen, scaling(index))))
        if best is None or clearly_greater(value, best[0]):
            best = (value, chosen, swaps)
    assert best is not None  # both start counts are positive
    return best[1], best[2]


def _refined(setup, workspace, row_model: RowModel, info: Information, chosen: tuple,
             spectrum: np.ndarray, index: str, rounds: int) -> tuple[tuple, np.ndarray, bool]:
    """``(candidates, spectrum, refined)`` after up to ``rounds`` continuous refinements,
    stopping at the first that does not help."""
    refined = False
    for _ in range(rounds):
        better = refine_plan(setup, workspace, row_model, info, chosen, index)
        if better is None:
            break
        chosen, spectrum = better
        refined = True
    return chosen, spectrum, refined


def _random_plans(setup, row_model: RowModel, info: Information, candidates, count: int,
                  index: str, rng: np.random.Generator
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random feasible plans of ``count`` for comparison: their index values, predicted
    tool errors [m] and exact condition numbers."""
    randoms = random_designs(info, count, RANDOM_PLANS, rng)
    random_values = np.array([index_value(index, info.spectrum(d, scaling(index)))
                              for d in randoms])
    random_tool = np.array([tool_error(info.spectrum(d, "tool"), setup.noise) for d in randoms])
    random_condition = np.array([exact_condition(row_model.blocks([candidates[i] for i in d]),
                                                 row_model.parameters, row_model.shared)
                                 for d in randoms])
    return random_values, random_tool, random_condition
