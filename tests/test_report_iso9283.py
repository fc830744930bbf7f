"""ISO 9283 accuracy and repeatability against closed forms on hand-made residuals."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from test_report import synthetic_result

from robocal_casadi.report.content import Paragraph, Table
from robocal_casadi.report.iso9283 import (
    POSE_TOLERANCE,
    accuracy_lines,
    repeatability,
    same_poses,
)
from robocal_casadi.report.sections import build_document
from robocal_casadi.results import DatasetResiduals, ErrorTerm

R1, R2 = 20e-6, 50e-6  # [m] radii of the two shells of visits about one barycentre
CENTRE = np.array([3e-4, -2e-4, 1e-4])  # [m] the pose's mean error: a bias, not a scatter


def _octahedron(radius: float, turn: float) -> np.ndarray:
    """Six points at ``radius`` along +-x, +-y, +-z turned by ``turn`` about z: their mean
    is exactly the origin."""
    c, s = np.cos(turn), np.sin(turn)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return radius * np.vstack([np.eye(3), -np.eye(3)]) @ R.T


def _tracker(rng: np.random.Generator, repeats: dict[int, np.ndarray], rows: int = 40,
             label: str = "cell.yaml") -> DatasetResiduals:
    """Tracker residuals: distinct random poses, then for each ``repeats`` entry the pose
    of that row visited again once per offset (N x 3 [m] about ``CENTRE``), the joint
    readings jittered by a third of the tolerance."""
    joints = [rng.uniform(-2, 2, (rows, 6))]
    parts = [rng.normal(0, 1e-4, (rows, 3))]
    for row, offsets in repeats.items():
        jitter = rng.uniform(-1, 1, (len(offsets), 6)) * POSE_TOLERANCE / 3
        joints.append(joints[0][row] + jitter)
        parts.append(CENTRE + offsets)
        parts[0][row] = CENTRE + offsets[0]
        joints[-1], parts[-1] = joints[-1][1:], parts[-1][1:]  # the first visit is ``row``
    Q, E = np.vstack(joints), np.vstack(parts)
    norm = np.linalg.norm(E, axis=1)
    return DatasetResiduals(label, "tracker_points", norm, 0.5 * norm, 0.25 * norm,
                            np.arange(len(Q)), Q, components={"nominal": E, "geometric": E / 2,
                                                              "final": E / 4},
                            terms=(ErrorTerm("position"),) * len(Q), frame="instrument")


def _with(residuals: tuple, validation: tuple = ()):
    return replace(synthetic_result(validation=False), residuals=residuals,
                   validation_residuals=validation)


def test_repeatability_of_two_shells_equals_the_closed_form():
    """Twelve visits of one pose, six at R1 and six at R2 from their barycentre: the mean
    distance is (R1 + R2) / 2, the sample deviation sqrt(12 ((R2 - R1) / 2)^2 / 11), and
    RP = mean + 3 deviation; the other forty poses are visited once and give nothing."""
    rng = np.random.default_rng(1)
    offsets = np.vstack([_octahedron(R1, 0.3), _octahedron(R2, 1.1)])
    found = repeatability(_with((_tracker(rng, {7: offsets}),)))
    assert len(found.poses) == 1
    pose = found.poses[0]
    mean = (R1 + R2) / 2
    std = np.sqrt(12 * ((R2 - R1) / 2) ** 2 / 11)
    assert pose.visits == 12 and pose.line == 7 + 2
    assert pose.spread.mean == pytest.approx(mean, rel=1e-12)
    assert pose.spread.std == pytest.approx(std, rel=1e-12)
    assert pose.spread.rp == pytest.approx(mean + 3 * std, rel=1e-12)


def test_overall_pools_the_distances_of_every_repeated_pose():
    """Two poses on one shell each (radius R1 and R2): each pose's RP is its radius (no
    spread); pooled, twelve distances of two values, as in the two-shell closed form."""
    rng = np.random.default_rng(2)
    fit = _tracker(rng, {3: _octahedron(R1, 0.0)})
    held = _tracker(rng, {5: _octahedron(R2, 0.7)}, label="validation:cell")
    found = repeatability(_with((fit,), (held,)))
    assert [(p.role, p.visits) for p in found.poses] == [("fit", 6), ("validation", 6)]
    assert [p.spread.rp for p in found.poses] == pytest.approx([R1, R2], rel=1e-12, abs=1e-18)
    (measure, pooled), = found.overall
    assert measure == ("position", "instrument") and pooled.count == 12
    assert pooled.rp == pytest.approx((R1 + R2) / 2 + 3 * np.sqrt(3 * (R2 - R1) ** 2 / 11),
                                      rel=1e-12)


def test_laser_readings_repeat_along_the_beam():
    """A sphere scan that reads one pose four times, at c -+ a and c -+ b: the distances to
    the mean reading are a, a, b, b."""
    a, b, c = 4e-6, 10e-6, 2e-4
    joints = np.vstack([np.zeros((4, 6)), np.arange(30).reshape(5, 6) * 0.1])
    signed = np.concatenate([[c - a, c + a, c - b, c + b], np.full(5, 1e-4)])
    parts = np.full((9, 3), np.nan)
    parts[:, 0] = signed
    scan = DatasetResiduals("scan", "sphere_laser", np.abs(signed), np.abs(signed),
                            np.abs(signed), np.arange(9), joints,
                            components={"nominal": parts}, terms=(ErrorTerm("surface"),) * 9)
    (pose,) = repeatability(_with((scan,))).poses
    distances = np.array([a, a, b, b])
    assert pose.spread.mean == pytest.approx(distances.mean(), rel=1e-12)
    assert pose.spread.std == pytest.approx(np.std(distances, ddof=1), rel=1e-12)


def test_same_poses_tolerance():
    """Readings within the tolerance (chained) form one pose; a step of 10x it does not."""
    base = np.full(6, 0.4)
    Q = np.vstack([base, base + 0.6 * POSE_TOLERANCE, base + 1.2 * POSE_TOLERANCE,
                   base + 10 * POSE_TOLERANCE, base + 1.0])
    groups = same_poses(Q)
    assert [g.tolist() for g in groups] == [[0, 1, 2]]


def test_accuracy_is_the_mean_and_sample_spread_of_each_measure():
    """Tracker positions and bar lengths are summarised apart, each equal to numpy."""
    result = synthetic_result(bar=True, validation=False)
    tracker = replace(result.residuals[0], terms=(ErrorTerm("position"),)
                      * len(result.residuals[0].rows), frame="instrument")
    bar = result.residuals[1]
    kinds = np.where(np.asarray(bar.rows) >= 0, "position", "distance")
    bar = replace(bar, terms=tuple(ErrorTerm(str(k)) for k in kinds), frame="base")
    lines = {(line.measure, line.model): line.spread
             for line in accuracy_lines(replace(result, residuals=(tracker, bar)))}
    expected = {("position", "instrument"): tracker.errors_final,
                ("position", "base"): bar.errors_final[kinds == "position"],
                ("distance", ""): bar.errors_final[kinds == "distance"]}
    for measure, errors in expected.items():
        spread = lines[(measure, "final")]
        magnitude = np.abs(errors)
        assert spread.count == magnitude.size
        assert spread.mean == pytest.approx(magnitude.mean(), rel=1e-12)
        assert spread.std == pytest.approx(np.std(magnitude, ddof=1), rel=1e-12)
        assert spread.max == pytest.approx(magnitude.max(), rel=1e-12)


def _accuracy_section(result):
    return next(s for s in build_document(result).sections if s.anchor == "accuracy")


def test_report_says_plainly_when_no_pose_was_repeated():
    rng = np.random.default_rng(3)
    section = _accuracy_section(_with((_tracker(rng, {}),)))
    texts = [b.text for b in section.blocks if isinstance(b, Paragraph)]
    assert any("no repeated visit of a pose" in t and "none can be given" in t for t in texts)
    assert not any(isinstance(b, Table) and b.name == "repeatability" for b in section.blocks)


def test_report_table_shows_the_pooled_and_each_pose_in_millimetres():
    rng = np.random.default_rng(4)
    offsets = np.vstack([_octahedron(R1, 0.3), _octahedron(R2, 1.1)])
    section = _accuracy_section(_with((_tracker(rng, {7: offsets}),)))
    table = next(b for b in section.blocks if isinstance(b, Table) and b.name == "repeatability")
    mean = (R1 + R2) / 2
    rp = mean + 3 * np.sqrt(12 * ((R2 - R1) / 2) ** 2 / 11)
    assert table.rows[1][:4] == ("cell.yaml", "fit", "9", "12")
    for row in table.rows:
        assert float(row[4]) == pytest.approx(mean * 1e3, rel=1e-3)
        assert float(row[6]) == pytest.approx(rp * 1e3, rel=1e-3)


def test_bar_data_state_what_the_statistic_is_instead():
    result = synthetic_result(bar=True, validation=False)
    bar = result.residuals[1]
    bar = replace(bar, terms=tuple(ErrorTerm("position" if k >= 0 else "distance")
                                   for k in bar.rows), frame="base")
    section = _accuracy_section(replace(result, residuals=(bar,)))
    texts = " ".join(b.text for b in section.blocks if isinstance(b, Paragraph))
    assert "measure no absolute position" in texts
    assert "cannot be given" in texts  # neither accuracy of positions nor repeatability
