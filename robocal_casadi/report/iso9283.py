"""Position accuracy and repeatability in the manner of ISO 9283, as far as the data allow.

Accuracy: ISO 9283 judges a robot by the distance between the position it was commanded
to and the position it reached. A tracker measures that position, so the length of each
reading's 3-D error is such a distance; the table gives its mean and spread (sample
standard deviation) and maximum [m] under each model. The other kinds measure something
else, and the same statistics are of that (``MEASURES``): a bar or an artifact's known
lengths (no absolute position at all), a touch's distance from its socket's fitted
centre (the same point reached from different joint configurations), a laser point's
distance from a sphere surface (along the beam, in a small region).

Repeatability: when the data visit one pose more than once (rows of a dataset whose
joint readings agree to within ``POSE_TOLERANCE``), the positions reached on those
visits scatter about their barycentre; with ``l_j`` the distance of visit ``j`` from it,
``RP = mean(l) + 3 S_l`` where ``S_l`` is the sample standard deviation of the ``l_j``
(ISO 9283, 7.2.2). Computed per repeated pose and over all of them (the distances
pooled, each to its own pose's barycentre). The positions come from the measurements
alone: within one pose the model's prediction is the same on every visit, so the
spread of ``measured - predicted`` is the spread of what was measured. Only readings an
instrument takes count (a tracker's point in 3-D, a laser's distance along its beam in
1-D); a touch of a socket reaches the socket by construction and says nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..results import CalibrationResult, DatasetResiduals
from .errors_table import csv_line
from .numbers import MODELS

# [rad] or [m] for a prismatic joint: readings of one pose visited again agree to the
# controller's last logged digit, while distinct calibration poses differ by degrees. A
# joint difference of 1e-6 rad moves a point 2 m from the axis by 2 um, below any
# instrument's noise, so treating such readings as one pose costs nothing.
POSE_TOLERANCE = 1e-6

# What the errors of each term measure (term kind, component frame) -> words, and
# whether that is an absolute position (the ISO 9283 quantity).
MEASURES = {
    ("position", "instrument"): ("position error (measured minus predicted point)", True),
    ("position", "base"): ("distance of a touch from its socket's fitted centre", False),
    ("surface", ""): ("distance of a laser point from the sphere surface", False),
    ("distance", ""): ("deviation of a known length", False),
    ("perpendicular", ""): ("perpendicularity error AC.BD / L", False),
    ("error", ""): ("error", False),
}
REPEATABLE = {("position", "instrument"), ("surface", "")}
REPEATED_WORDS = {("position", "instrument"): "points in space",
                  ("surface", ""): "laser readings along the beam"}


@dataclass(frozen=True)
class Spread:
    """Mean, sample standard deviation and maximum of ``count`` distances [m]."""

    count: int
    mean: float
    std: float
    max: float

    @property
    def rp(self) -> float:
        """``mean + 3 std`` [m]: ISO 9283's repeatability when the distances are taken to
        the barycentre of repeated visits."""
        return self.mean + 3.0 * self.std

    @staticmethod
    def of(distances: np.ndarray) -> Spread:
        d = np.abs(np.asarray(distances, dtype=float))
        if d.size == 0:
            return Spread(0, float("nan"), float("nan"), float("nan"))
        std = float(np.std(d, ddof=1)) if d.size > 1 else float("nan")
        return Spread(int(d.size), float(d.mean()), std, float(d.max()))


def measure_of(residuals: DatasetResiduals, kind: str) -> tuple[str, str]:
    """The ``MEASURES`` key of errors of term ``kind`` in ``residuals``."""
    frame = residuals.frame if kind == "position" else ""
    key = (kind, frame)
    return key if key in MEASURES else ("error", "")


def term_kinds(residuals: DatasetResiduals) -> np.ndarray:
    """The term kind of each error (``"error"`` where none was recorded)."""
    if residuals.terms:
        return np.array([t.kind for t in residuals.terms])
    return np.full(len(residuals.errors_final), "error")


@dataclass(frozen=True)
class AccuracyLine:
    """``spread`` [m] of the errors of one measure (``MEASURES`` key) under ``model``."""

    role: str
    measure: tuple[str, str]
    model: str
    spread: Spread


def accuracy_lines(result: CalibrationResult) -> list[AccuracyLine]:
    """Per role (fit, validation), per measure and per model, the error statistics."""
    out = []
    for role, group in (("fit", result.residuals), ("validation", result.validation_residuals)):
        pooled: dict[tuple[str, str], dict[str, list[np.ndarray]]] = {}
        for r in group:
            kinds = term_kinds(r)
            for kind in dict.fromkeys(kinds.tolist()):
                chosen = kinds == kind
                entry = pooled.setdefault(measure_of(r, kind), {m: [] for m in MODELS})
                for m in MODELS:
                    entry[m].append(np.asarray(getattr(r, f"errors_{m}"), float)[chosen])
        for measure, entry in pooled.items():
            for m in MODELS:
                out.append(AccuracyLine(role, measure, m, Spread.of(np.concatenate(entry[m]))))
    return out


def same_poses(joints: np.ndarray, tolerance: float = POSE_TOLERANCE) -> list[np.ndarray]:
    """Groups of row indices (two or more, ascending, groups by first row) whose joint
    readings (N x dof, SI) all agree to within ``tolerance`` (chained: a row within
    ``tolerance`` of any row of a group joins it)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    Q = np.asarray(joints, dtype=float)
    if len(Q) < 2:
        return []
    pairs = cKDTree(Q).query_pairs(tolerance, p=np.inf, output_type="ndarray")
    if not len(pairs):
        return []
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(Q),) * 2)
    _, labels = connected_components(graph, directed=False)
    groups = [np.flatnonzero(labels == label) for label in np.unique(labels[pairs[:, 0]])]
    return sorted(groups, key=lambda g: int(g[0]))


def barycentre_distances(points: np.ndarray) -> np.ndarray:
    """Distance [m] of each of ``points`` (n x k) from their barycentre."""
    points = np.asarray(points, dtype=float)
    return np.linalg.norm(points - points.mean(axis=0), axis=1)


@dataclass(frozen=True)
class PoseRepeatability:
    """One pose visited ``visits`` times: the distances to the barycentre (``spread``,
    [m]), what was measured (``MEASURES`` key) and the CSV line of the first visit."""

    dataset: str
    role: str
    line: int
    visits: int
    measure: tuple[str, str]
    spread: Spread


@dataclass(frozen=True)
class Repeatability:
    """Every repeated pose found, and per measure (``MEASURES`` key) the spread of the
    distances of all of them pooled (empty: no pose visited twice)."""

    poses: tuple[PoseRepeatability, ...]
    overall: tuple[tuple[tuple[str, str], Spread], ...] = ()

    @property
    def found(self) -> bool:
        return bool(self.poses)


def repeatability(result: CalibrationResult, tolerance: float = POSE_TOLERANCE
                  ) -> Repeatability:
    """Repeatability of the instrument readings of ``result``'s datasets, fit and held out."""
    poses: list[PoseRepeatability] = []
    distances: dict[tuple[str, str], list[np.ndarray]] = {}
    for role, group in (("fit", result.residuals), ("validation", result.validation_residuals)):
        for r in group:
            for pose, d in _dataset_repeats(r, role, tolerance):
                poses.append(pose)
                distances.setdefault(pose.measure, []).append(d)
    overall = tuple((m, Spread.of(np.concatenate(d))) for m, d in distances.items())
    return Repeatability(tuple(poses), overall)


def _dataset_repeats(r: DatasetResiduals, role: str, tolerance: float):
    """``(PoseRepeatability, distances [m])`` per repeated pose of one dataset."""
    parts = r.components.get("nominal")
    if r.joints is None or parts is None or len(parts) != len(r.errors_final):
        return []
    rows = np.asarray(r.rows, dtype=int)
    kinds = term_kinds(r)
    out = []
    for kind in dict.fromkeys(kinds.tolist()):
        measure = measure_of(r, kind)
        if measure not in REPEATABLE:
            continue
        entries = np.flatnonzero((kinds == kind) & (rows >= 0))
        entry_of_row = {int(rows[i]): int(i) for i in entries}
        width = 3 if kind == "position" else 1
        for group in same_poses(np.asarray(r.joints)[sorted(entry_of_row)], tolerance):
            data_rows = np.asarray(sorted(entry_of_row))[group]
            points = np.asarray(parts)[[entry_of_row[int(k)] for k in data_rows], :width]
            d = barycentre_distances(points)
            out.append((PoseRepeatability(r.label, role, csv_line(r, int(data_rows[0])),
                                          len(group), measure, Spread.of(d)), d))
    return out


# ----------------------------------------------------------------------------- report blocks

INSTEAD = {  # what a measure that is no absolute position gives instead, in words
    ("position", "base"): "touches of a socket measure no position: the statistic is each "
                          "touch's distance from the socket's fitted centre, how closely the "
                          "model brings the probe to one point from different joint "
                          "configurations",
    ("surface", ""): "laser points on a sphere measure no position: the statistic is each "
                     "point's distance from the sphere surface, along the beam and over the "
                     "small region around the sphere",
    ("distance", ""): "known lengths (a bar, an artifact's sockets) measure no absolute "
                      "position: the statistic is the deviation of each length",
    ("perpendicular", ""): "a perpendicularity measures no position: the statistic is "
                           "AC.BD / L, a length",
}
POSES_SHOWN = 12  # repeated poses listed in the main text, largest RP first
VISITS_ASKED = 30  # ISO 9283's cycles per pose for repeatability


def iso9283_blocks(result: CalibrationResult, units) -> list:
    """The report's ISO 9283 part: accuracy by measure, then repeatability or why none.
    ``units``: the display units (lengths shown in ``units.length``)."""
    from .content import Paragraph

    lines = accuracy_lines(result)
    if not lines:
        return []
    measures = list(dict.fromkeys(line.measure for line in lines))
    words = ["Position accuracy in the manner of ISO 9283: per reading, the distance between "
             "where the model puts the tool and where the instrument found it; mean, sample "
             "standard deviation (the spread) and maximum."]
    words += [f"{INSTEAD[m][:1].upper()}{INSTEAD[m][1:]}." for m in measures if m in INSTEAD]
    if not any(MEASURES[m][1] for m in measures):
        words[0] = ("These data measure no absolute position, so ISO 9283's position "
                    "accuracy cannot be given; the table shows what they measure instead.")
    blocks: list = [Paragraph("Accuracy and repeatability (ISO 9283)", "heading"),
                    Paragraph(" ".join(words)), _accuracy_table(result, lines, units)]
    return blocks + _repeatability_blocks(repeatability(result), measures, units)


def _accuracy_table(result: CalibrationResult, lines: list[AccuracyLine], units):
    from .content import Table
    from .numbers import MODEL_TITLES, format_number

    shown = MODELS if result.effects else ("nominal", "final")
    s = units.length_scale
    rows, muted = [], []
    for line in lines:
        if line.model not in shown:
            continue
        model = "calibrated" if not result.effects and line.model == "final" else \
            MODEL_TITLES[line.model]
        a = line.spread
        rows.append((line.role, MEASURES[line.measure][0], model, str(a.count),
                     *(format_number(v / s) for v in (a.mean, a.std, a.max))))
        muted.append(line.model == "nominal")
    return Table("iso-accuracy", f"Accuracy by what was measured [{units.length}]",
                 ("data", "measured", "model", "readings", "mean", "standard deviation",
                  "maximum"), tuple(rows), tuple(muted),
                 (False, False, False, True, True, True, True))


def _repeatability_blocks(found: Repeatability, measures: list, units) -> list:
    from .content import Details, Paragraph, Table
    from .numbers import format_number

    if not any(m in REPEATABLE for m in measures):
        return [Paragraph("Repeatability: none can be given. These data hold no instrument "
                          "reading of a position (touches reach their socket by "
                          "construction), so visiting a pose again would show no scatter.",
                          "note")]
    if not found.found:
        return [Paragraph(f"Repeatability: none can be given. The data hold no repeated visit "
                          f"of a pose (no two readings of a dataset with joint readings equal "
                          f"to within {POSE_TOLERANCE * 1e6:g} µrad). To state it, measure a few "
                          f"poses several times each (ISO 9283 asks for {VISITS_ASKED}).",
                          "conclusion")]
    s = units.length_scale

    def cells(spread: Spread) -> tuple[str, ...]:
        return tuple(format_number(v / s) for v in (spread.mean, spread.std, spread.rp))

    header = ("dataset", "role", "line of first visit", "visits",
              "mean distance to barycentre", "standard deviation", "RP")
    numeric = (False, False, True, True, True, True, True)
    ordered = sorted(found.poses, key=lambda p: -p.spread.rp if np.isfinite(p.spread.rp)
                     else 0.0)
    rows = [(p.dataset, p.role, str(p.line), str(p.visits), *cells(p.spread)) for p in ordered]
    overall = [(f"all repeated poses, {REPEATED_WORDS[m]}", "-", "-", str(spread.count),
                *cells(spread)) for m, spread in found.overall]
    text = (f"Repeatability RP = mean + 3 standard deviations of the distances of repeated "
            f"visits from their barycentre (ISO 9283), from the measurements alone, "
            f"[{units.length}]. {len(found.poses)} pose(s) were visited more than once.")
    blocks: list = [Paragraph(text),
                    Table("repeatability", f"Repeatability [{units.length}]", header,
                          tuple(overall + rows[:POSES_SHOWN]), numeric=numeric)]
    if len(rows) > POSES_SHOWN:
        blocks.append(Details("repeatability-all", f"All {len(rows)} repeated poses",
                              (Table("repeatability-all", f"Every repeated pose "
                                     f"[{units.length}]", header, tuple(rows),
                                     numeric=numeric),)))
    if any(p.visits < VISITS_ASKED for p in found.poses):
        blocks.append(Paragraph(f"ISO 9283 asks for {VISITS_ASKED} visits per pose; with fewer, "
                                f"the standard deviation and so RP are uncertain.", "note"))
    return blocks
