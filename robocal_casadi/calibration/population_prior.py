"""A fleet's population prior on file, and its use in the next robot's calibration.

Three pieces (docs/formats.md#fleet-prior-file, docs/methods.md#fleet-prior):

* ``geometry_posterior.json`` in every calibration result folder (``write_posterior``):
  the geometric fit's estimate and posterior covariance of the robot parameters it
  fitted, with the prior it was fitted under (centre and covariance), in the robot file's
  units; ``read_calibration`` turns it back into the robot's ``population.Evidence``.
* ``PRIOR.yaml`` (``PopulationPrior``, ``save_prior``, ``load_prior``): the population of
  one model, mean deviation from nominal, spread and correlation per parameter, the
  robots it came from.
* ``prior_for``: a calibration's prior with the population in place of the tolerances of
  the robot parameters it covers (full covariance), the tolerance prior on the rest;
  ``PriorUse`` records which prior was used and whether this robot belongs.
"""

from __future__ import annotations

import datetime
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import yaml

from ..common.output import atomic_file
from ..common.units import Units, units_of
from ..errors import InputError
from . import population
from .population import Evidence, Membership, Population
from .prior import Prior, tolerance_of

POSTERIOR_FILE = "geometry_posterior.json"
PRIOR_KIND = "fleet_prior"
NOMINAL_RTOL = 1e-9  # relative difference of two nominal values still the same drawing


@dataclass(frozen=True)
class Calibration:
    """One robot's calibration as the population needs it: the ``model`` (robot name,
    ``convention``, every geometric parameter with its ``quantities`` and ``nominal``
    [SI]), the file ``units``, and the ``evidence`` over its fitted ``fitted`` names."""

    folder: Path
    model: str
    convention: str
    units: Units
    names: tuple[str, ...]
    quantities: tuple[str, ...]
    nominal: np.ndarray
    tolerance: np.ndarray
    fitted: tuple[str, ...]
    evidence: Evidence

    def same_model(self, other: Calibration) -> str | None:
        """Why ``other`` is not of this robot model (None: it is)."""
        if other.model != self.model:
            return f"robot {other.model!r}, not {self.model!r}"
        if other.convention != self.convention or other.names != self.names:
            return f"another parameter set ({other.convention}) than {self.folder}"
        scale = np.maximum(np.abs(self.nominal), 1e-3)
        off = np.flatnonzero(np.abs(other.nominal - self.nominal) > NOMINAL_RTOL * scale)
        if len(off):
            return (f"another nominal robot file than {self.folder} "
                    f"({self.names[int(off[0])]} differs)")
        return None


def write_posterior(result, folder: Path) -> Path | None:
    """``geometry_posterior.json`` in ``folder`` from ``result`` (None: no posterior)."""
    content = posterior_content(result)
    if content is None:
        return None
    path = Path(folder) / POSTERIOR_FILE
    path.write_text(json.dumps(content, indent=1) + "\n")
    return path


def posterior_content(result) -> dict | None:
    """The content of ``geometry_posterior.json`` for ``result`` (file units; None when
    the geometric fit has no posterior covariance)."""
    robot = result.robot_nominal
    registry = robot.parameters()
    names = [n for n in result.covariance_names if n in registry]
    if not names or not np.size(result.covariance):
        return None
    units = robot.units
    position = [result.covariance_names.index(n) for n in names]
    covariance = np.asarray(result.covariance, float)[np.ix_(position, position)]
    estimate = {p.name: p.estimate for p in result.parameters_geometric}
    nominal = robot.parameter_vector()
    scale = np.array([units.scale(registry.quantity(n)) for n in registry.names])
    fitted_scale = np.array([units.scale(registry.quantity(n)) for n in names])
    prior = _prior_block(result, names)
    content = {
        "model": robot.name, "convention": robot.convention, "units": units.as_dict(),
        "parameters": [{"name": n, "unit": units.unit_name(q), "nominal": float(v / s),
                        "tolerance": _none(tolerance_of(n, q, robot), s)}
                       for n, q, v, s in zip(registry.names, registry.quantities, nominal,
                                             scale)],
        "fitted": names,
        "estimate": [float(estimate[n] / s) for n, s in zip(names, fitted_scale)],
        "covariance": (covariance / np.outer(fitted_scale, fitted_scale)).tolist(),
        "prior": None if prior is None else {
            "source": prior[0],
            "centre": [float(c / s) for c, s in zip(prior[1], fitted_scale)],
            "covariance": (prior[2] / np.outer(fitted_scale, fitted_scale)).tolist()},
    }
    return content


def _none(value: float | None, scale: float) -> float | None:
    return None if value is None else float(value) / scale


def _prior_block(result, names: Sequence[str]) -> tuple[str, np.ndarray, np.ndarray] | None:
    """The prior the geometric fit was weighed with over ``names``: source, centre and
    covariance [SI]; None under least squares."""
    summary = result.prior
    if summary is None or not summary.tolerance:
        return None
    use = getattr(summary, "use", None)
    if isinstance(use, PriorUse) and use.names:
        position = [use.names.index(n) for n in names]
        return (use.source, use.centre[position],
                use.covariance[np.ix_(position, position)])
    robot = result.robot_nominal
    registry = robot.parameters()
    nominal = robot.parameter_vector()
    centre = np.array([nominal[registry.index(n)] for n in names])
    return "tolerance", centre, np.diag([summary.tolerance[n] ** 2 for n in names])


def read_calibration(folder: Path) -> Calibration:
    """The calibration in result folder ``folder`` (``InputError`` naming it when it is not
    one, or predates ``geometry_posterior.json``)."""
    folder = Path(folder)
    path = folder / POSTERIOR_FILE
    if not (folder / "result.json").is_file():
        raise InputError("not a calibration result folder (no result.json)", file=folder)
    if not path.is_file():
        raise InputError(f"no {POSTERIOR_FILE}: calibrate this robot again with this version",
                         file=folder)
    try:
        content = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise InputError(f"unreadable: {error}", file=path) from None
    return calibration_from(content, folder, path)


def calibration_from(content: dict, folder: Path, path: Path | None = None) -> Calibration:
    """The ``Calibration`` a ``geometry_posterior.json`` ``content`` describes (``folder``
    names the robot; ``path`` the file, for errors: ``InputError`` naming the key of
    anything missing, of the wrong size, not finite or not a covariance)."""
    path = path if path is not None else Path(folder) / POSTERIOR_FILE
    try:
        units = units_of(content, file=path)
        rows = content["parameters"]
        names = tuple(str(r["name"]) for r in rows)
        for k, r in enumerate(rows):
            if str(r["unit"]) not in (units.length, units.angle, ""):
                raise InputError(f"expected the file's units ({units.length} or "
                                 f"{units.angle}), got {r['unit']!r}", file=path,
                                 where=f"parameters[{k}].unit")
        quantities = tuple(_quantity(units, str(r["unit"])) for r in rows)
        scale = np.array([units.scale(q) for q in quantities])
        nominal = _finite(path, "parameters[].nominal",
                          [float(r["nominal"]) for r in rows]) * scale
        tolerance = np.array([np.nan if r["tolerance"] is None else float(r["tolerance"])
                              for r in rows]) * scale
        fitted = tuple(str(n) for n in content["fitted"])
        unknown = [n for n in fitted if n not in names]
        if unknown or len(set(fitted)) != len(fitted):
            raise InputError(f"{unknown[0]!r} is not among the parameters" if unknown else
                             "a parameter is listed twice", file=path, where="fitted")
        position = [names.index(n) for n in fitted]
        s = scale[position]
        nominal_fitted = nominal[position]
        n = len(fitted)
        estimate = _finite(path, "estimate", content["estimate"], (n,)) * s - nominal_fitted
        covariance = _covariance(path, "covariance", content["covariance"], n) * np.outer(s, s)
        prior = content["prior"]
        if prior is not None:
            centre = _finite(path, "prior.centre", prior["centre"], (n,)) * s - nominal_fitted
            prior_covariance = _covariance(path, "prior.covariance", prior["covariance"], n,
                                           definite=True) * np.outer(s, s)
        model, convention = str(content["model"]), str(content["convention"])
    except (KeyError, TypeError, ValueError, AttributeError) as error:
        raise InputError(f"unreadable: {error}", file=path) from None
    if prior is None:
        information = np.linalg.pinv(covariance, hermitian=True)
        evidence = Evidence(str(folder), information, information @ estimate)
    else:
        evidence = Evidence.from_posterior(str(folder), estimate, covariance, centre,
                                           prior_covariance)
    return Calibration(folder, model, convention, units, names, quantities, nominal, tolerance,
                       fitted, evidence)


def _finite(path: Path, key: str, values, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """``values`` as a finite array of ``shape`` (``InputError`` naming ``key`` if not)."""
    array = np.array(values, float)
    if shape is not None and array.shape != shape:
        raise InputError(f"expected {' x '.join(map(str, shape))} numbers, got "
                         f"{' x '.join(map(str, array.shape)) or 'one'}", file=path, where=key)
    if not np.all(np.isfinite(array)):
        raise InputError("expected finite numbers", file=path, where=key)
    return array


def _covariance(path: Path, key: str, values, n: int, definite: bool = False) -> np.ndarray:
    """``values`` as an ``n x n`` symmetric positive semi-definite (``definite``: positive
    definite) matrix, to rounding (``InputError`` naming ``key`` if not)."""
    matrix = _finite(path, key, values, (n, n))
    symmetric = 0.5 * (matrix + matrix.T)
    scale = float(np.max(np.abs(np.diag(symmetric)), initial=0.0))
    lowest = float(np.min(np.linalg.eigvalsh(symmetric))) if n else math.inf
    if not np.allclose(matrix, matrix.T, rtol=1e-6, atol=1e-12 * scale) or \
            lowest < -1e-9 * scale or (definite and not lowest > 0):
        kind = "definite" if definite else "semi-definite"
        raise InputError(f"expected a symmetric positive {kind} matrix (a covariance)",
                         file=path, where=key)
    return symmetric


def _quantity(units: Units, unit: str) -> str:
    if unit == units.length:
        return "length"
    if unit == units.angle:
        return "angle"
    return "none"


@dataclass(frozen=True)
class PopulationPrior(population.PopulationFigures):
    """A fleet's population prior of one robot model (``PRIOR.yaml``), SI inside: per
    parameter ``names`` its ``quantities``, ``nominal`` value, ``mean`` deviation from it
    and the ``covariance`` of the deviations; ``seen_by`` robots whose data decided at
    least half of it; the ``robots`` (and their ``members`` statistics) it came from."""

    model: str
    convention: str
    units: Units
    date: str
    robots: tuple[str, ...]
    names: tuple[str, ...]
    quantities: tuple[str, ...]
    nominal: np.ndarray
    mean: np.ndarray
    covariance: np.ndarray
    seen_by: tuple[int, ...]
    members: tuple[Membership, ...] = ()
    pseudo_robots: float = population.PSEUDO_ROBOTS
    path: Path | None = None
    fitted_by: tuple[int, ...] = ()  # robots whose calibration fitted it (empty: not known)

    def fitted(self) -> tuple[str, ...]:
        """The parameters some robot's calibration fitted (its data could see them); every
        parameter of the prior when that is not known (a file written by hand)."""
        if not self.fitted_by:
            return self.names
        return tuple(n for n, k in zip(self.names, self.fitted_by) if k > 0)


    def check_robot(self, robot, file) -> None:
        """Refuse (``InputError`` naming ``file``) a robot not of this model."""
        registry = robot.parameters()
        if robot.convention != self.convention or tuple(registry.names) != self.names:
            raise InputError(f"a prior of {self.model!r} ({self.convention}, "
                             f"{len(self.names)} parameters) does not fit robot "
                             f"{robot.name!r} ({robot.convention}, {len(registry)} parameters"
                             f"{_first_difference(self.names, tuple(registry.names))})",
                             file=file)
        nominal = robot.parameter_vector()
        scale = np.maximum(np.abs(self.nominal), 1e-3)
        off = np.flatnonzero(np.abs(nominal - self.nominal) > NOMINAL_RTOL * scale)
        if len(off):
            k = int(off[0])
            quantity = self.quantities[k]
            unit = self.units.unit_name(quantity)
            scale_k = self.units.scale(quantity)
            whose = (f"robot {self.model!r}, not {robot.name!r}" if self.model != robot.name
                     else "another nominal robot")
            raise InputError(f"a prior of {whose}: {self.names[k]} is "
                             f"{self.nominal[k] / scale_k:.9g}{' ' + unit if unit else ''} in "
                             f"the prior, {nominal[k] / scale_k:.9g}"
                             f"{' ' + unit if unit else ''} in robot {robot.name!r}", file=file)


def _first_difference(prior: Sequence[str], robot: Sequence[str]) -> str:
    """Where two parameter lists part, in words (empty when they agree)."""
    for k, (a, b) in enumerate(zip(prior, robot)):
        if a != b:
            return f"; parameter {k + 1} is {a!r} in the prior, {b!r} in the robot"
    if len(prior) != len(robot):
        longer, which = (prior, "prior") if len(prior) > len(robot) else (robot, "robot")
        return f"; the {which} goes on with {longer[min(len(prior), len(robot))]!r}"
    return ""


def learn(calibrations: Sequence[Calibration],
          pseudo_robots: float = population.PSEUDO_ROBOTS) -> PopulationPrior:
    """The population prior from ``calibrations`` of one model (``InputError`` naming the
    first folder of another model)."""
    first = calibrations[0]
    for other in calibrations[1:]:
        why = first.same_model(other)
        if why is not None:
            raise InputError(f"not the model of the others: {why}", file=other.folder)
    size = len(first.names)
    evidence = [c.evidence.embedded([first.names.index(n) for n in c.fitted], size)
                for c in calibrations]
    tolerance = np.where(np.isfinite(first.tolerance), first.tolerance, _fallback(first))
    fitted = population.estimate(evidence, first.names, tolerance, pseudo_robots)
    fitted_by = tuple(sum(n in c.fitted for c in calibrations) for n in first.names)
    return replace(from_population(fitted, first, tuple(str(c.folder) for c in calibrations),
                                   pseudo_robots), fitted_by=fitted_by)


def _fallback(calibration: Calibration) -> np.ndarray:
    """Tolerances [SI] for parameters without one: a generous 10 mm or 1 degree."""
    return np.array([10e-3 if q == "length" else math.radians(1.0)
                     for q in calibration.quantities])


def from_population(fitted: Population, model: Calibration, robots: tuple[str, ...],
                    pseudo_robots: float) -> PopulationPrior:
    return PopulationPrior(model.model, model.convention, model.units,
                           datetime.date.today().isoformat(), robots, model.names,
                           model.quantities, model.nominal, fitted.mean, fitted.covariance,
                           fitted.seen_by, fitted.members, pseudo_robots)


def save_prior(prior: PopulationPrior, path: Path) -> None:
    """``PRIOR.yaml`` in the model's file units, written whole or not at all."""
    units = prior.units
    scale = np.array([units.scale(q) for q in prior.quantities])
    spread = prior.spread
    correlation = prior.covariance / np.outer(spread, spread)
    content = {
        "kind": PRIOR_KIND, "model": prior.model, "convention": prior.convention,
        "units": units.as_dict(), "date": prior.date, "count": len(prior.robots),
        "robots": list(prior.robots), "pseudo_robots": float(prior.pseudo_robots),
        "odd": [_member(m) for m in prior.odd],
        "members": [_member(m) for m in prior.members],
        "parameters": [{"name": n, "unit": units.unit_name(q), "nominal": float(v / s),
                        "mean": float(m / s), "spread": float(d / s), "seen_by": int(k),
                        **({"fitted_by": int(prior.fitted_by[i])} if prior.fitted_by else {})}
                       for i, (n, q, v, m, d, s, k) in enumerate(zip(
                           prior.names, prior.quantities, prior.nominal, prior.mean, spread,
                           scale, prior.seen_by))],
        "correlation": [[float(v) for v in row] for row in correlation],
    }
    with atomic_file(path) as staging:
        Path(staging).write_text(yaml.safe_dump(content, sort_keys=False, width=100))


def _member(m: Membership) -> dict:
    return {"robot": m.robot, "distance": float(m.distance), "seen": int(m.seen),
            "threshold": float(m.threshold) if math.isfinite(m.threshold) else None,
            "weight": float(m.weight), "belongs": bool(m.belongs)}


def load_prior(path: Path) -> PopulationPrior:
    """``PRIOR.yaml`` back (``InputError`` naming the file and key on anything wrong)."""
    path = Path(path)
    try:
        content = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        raise InputError(f"not YAML: {' '.join(str(error).split())}", file=path) from None
    if not isinstance(content, dict) or content.get("kind") != PRIOR_KIND:
        raise InputError(f"expected a fleet prior (kind: {PRIOR_KIND}), as "
                         "`robocal prior` writes", file=path, where="kind")
    units = units_of(content, file=path)
    rows = content.get("parameters")
    if not isinstance(rows, list) or not rows:
        raise InputError("expected a list of parameters", file=path, where="parameters")
    names, quantities, values, fitted_by = [], [], [], []
    for k, row in enumerate(rows):
        try:
            fitted_by.append(int(row.get("fitted_by", -1)))
            names.append(str(row["name"]))
            unit = str(row["unit"])
            values.append([float(row[key]) for key in ("nominal", "mean", "spread")]
                          + [int(row["seen_by"])])
        except (KeyError, TypeError, ValueError, AttributeError) as error:
            raise InputError(f"expected name, unit, nominal, mean, spread, seen_by: {error}",
                             file=path, where=f"parameters[{k}]") from None
        _check_row(path, k, units, unit, values[-1], fitted_by[-1], "fitted_by" in row)
        quantities.append(_quantity(units, unit))
    if len(set(names)) != len(names):
        twice = next(n for n in names if names.count(n) > 1)
        raise InputError(f"{twice!r} is listed twice", file=path, where="parameters")
    table = np.array(values, float)
    scale = np.array([units.scale(q) for q in quantities])
    spread = table[:, 2] * scale
    if not np.all(np.isfinite(spread)) or np.any(spread <= 0):
        raise InputError("every spread must be a positive number", file=path,
                         where="parameters")
    try:
        correlation = np.array(content["correlation"], float)
        if correlation.shape != (len(names), len(names)):
            raise ValueError(f"a {len(names)} x {len(names)} matrix, got {correlation.shape}")
        covariance = correlation * np.outer(spread, spread)
        np.linalg.cholesky(0.5 * (covariance + covariance.T))
    except (KeyError, TypeError, ValueError, np.linalg.LinAlgError) as error:
        raise InputError(f"expected a positive definite correlation matrix: {error}",
                         file=path, where="correlation") from None
    robots = tuple(str(r) for r in content.get("robots") or ())
    return PopulationPrior(str(content.get("model", "")), str(content.get("convention", "")),
                           units, str(content.get("date", "")), robots, tuple(names),
                           tuple(quantities), table[:, 0] * scale, table[:, 1] * scale,
                           covariance, tuple(int(v) for v in table[:, 3]), (),
                           float(content.get("pseudo_robots", population.PSEUDO_ROBOTS)), path,
                           () if min(fitted_by) < 0 else tuple(fitted_by))


def _check_row(path: Path, k: int, units: Units, unit: str, values: list,
               fitted_by: int, has_fitted_by: bool) -> None:
    """One parameter row of ``PRIOR.yaml``: a unit of the file's, finite numbers, counts
    of robots that are not negative (``InputError`` naming the key)."""
    where = f"parameters[{k}]"
    if unit not in (units.length, units.angle, ""):
        raise InputError(f"expected the file's units ({units.length} or {units.angle}), got "
                         f"{unit!r}", file=path, where=f"{where}.unit")
    for key, value in zip(("nominal", "mean", "spread"), values):
        if not math.isfinite(value):
            raise InputError(f"expected a finite number, got {value}", file=path,
                             where=f"{where}.{key}")
    if values[3] < 0:
        raise InputError(f"expected a count of robots (0 or more), got {values[3]}",
                         file=path, where=f"{where}.seen_by")
    if has_fitted_by and fitted_by < 0:
        raise InputError(f"expected a count of robots (0 or more), got {fitted_by}",
                         file=path, where=f"{where}.fitted_by")


@dataclass(frozen=True)
class PriorUse:
    """Which prior a calibration used: ``source`` ``"tolerance"`` or the population
    prior's file; ``offered`` the population file when one was given; ``belongs``
    whether this robot's data agree with it (None: none offered) with the statistic
    ``member``; ``names``, ``centre`` [SI] and ``covariance`` [SI^2] the prior used over
    the fitted robot and mounted parameters."""

    source: str = "tolerance"
    offered: str | None = None
    belongs: bool | None = None
    member: Membership | None = None
    names: tuple[str, ...] = ()
    centre: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), repr=False)

    @property
    def sentence(self) -> str:
        """One line for the terminal ('' when no population prior was offered)."""
        if self.offered is None or self.member is None:
            return ""
        m = self.member
        if m.seen == 0:
            return (f"fleet prior {self.offered}: used; whether this robot belongs cannot be "
                    f"judged: its data see none of the directions the population covers")
        figure = (f"prior-data conflict {m.distance:.3g} over {m.seen} directions seen, "
                  f"limit {m.threshold:.3g}")
        if self.belongs:
            return f"fleet prior {self.offered}: this robot belongs ({figure}); used"
        return (f"THIS ROBOT DOES NOT BELONG to the fleet prior {self.offered}: its data "
                f"contradict the population beyond their noise ({figure}); calibrated with "
                f"the tolerance prior instead")

    def to_json(self) -> dict:
        out: dict = {"source": self.source, "belongs": self.belongs}
        if self.offered is not None:
            out["offered"] = self.offered
        if self.member is not None:
            out["conflict"] = {k: v for k, v in _member(self.member).items()
                               if k in ("distance", "seen", "threshold")}
        return out


def prior_for(problem, free: np.ndarray, sigma: float, fleet: PopulationPrior | None) -> Prior:
    """The prior on the free robot and mounted parameters of ``problem``: the tolerance
    prior, centred on their start values, with ``fleet``'s population (mean and full
    covariance) in place of it on the robot parameters the population covers."""
    start = problem.initial()
    index, tolerance = [], []
    for i in np.flatnonzero(free & problem.mask("robot", "mounted")):
        name = problem.unknowns.names[i]
        t = tolerance_of(name, problem.unknowns.quantity(name), problem.robot)
        if t is not None or (fleet is not None and name in fleet.names):
            index.append(int(i))
            tolerance.append(math.nan if t is None else t)
    index_array = np.array(index, dtype=int)
    names = tuple(problem.unknowns.names[i] for i in index_array)
    if fleet is None:
        return Prior(names, index_array, start[index_array], np.array(tolerance, float),
                     sigma)
    centre = start[index_array].copy()
    covariance = np.diag(np.array(tolerance, float) ** 2)
    covered = [k for k, n in enumerate(names) if n in fleet.names]
    where = [fleet.names.index(names[k]) for k in covered]
    centre[covered] = fleet.nominal[where] + fleet.mean[where]
    covariance[np.ix_(covered, covered)] = fleet.covariance[np.ix_(where, where)]
    return Prior.correlated(names, index_array, centre, covariance, sigma)


def judge(prior: Prior, posterior_covariance: np.ndarray, x: np.ndarray,
          fleet: PopulationPrior, robot: str) -> Membership:
    """Whether the calibration at ``x`` (posterior covariance over ``prior``'s parameters,
    [SI^2]) belongs to ``fleet``: the prior-predictive statistic over the parameters the
    population covers (``population.conflict``)."""
    covered = [k for k, n in enumerate(prior.names) if n in fleet.names]
    offset = np.asarray(x, float)[prior.index[covered]] - prior.centre[covered]
    prior_covariance = prior.covariance[np.ix_(covered, covered)]
    return population.conflict(robot, offset, prior_covariance,
                               posterior_covariance[np.ix_(covered, covered)])
