"""Point laser and sphere: the sensor-only fit, its identifiability check, the measurement
model, dataset checks, and robot plus sensor through ``calibrate``.

The truths are synthesised here with plain numpy (rotations by Rodrigues, standard DH by
hand, ray-sphere intersection), independently of the code under test.
"""

from __future__ import annotations

import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
import yaml

from robocal_casadi.errors import InputError
from robocal_casadi.instruments import INSTRUMENTS
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.instruments.laser.model import SphereLaserModel
from robocal_casadi.instruments.laser.sphere_fit import (
    Scan,
    algebraic_start,
    fit_dataset,
    fit_sensor,
    surface_residuals,
    tangent_basis,
)
from robocal_casadi.model import examples
from robocal_casadi.model.robot import save_robot

# The published method's example (docs/methods.md#point-laser-and-sphere):
# [x0, y0, z0, nx, ny, xc, yc, zc] in mm (nx, ny unitless).
PATENT = np.array([61.236, -15.643, 139.778, 0.016, 0.020, -119.193, -305.573, 106.620])
RADIUS = 0.025  # [m], our choice of sphere
NOISE = 0.01e-3  # [m], laser distance noise (standard deviation)


def patent_truth() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``p0`` [m], unit ``n``, ``c`` [m] of the published example (``nz > 0``)."""
    nx, ny = PATENT[3], PATENT[4]
    n = np.array([nx, ny, math.sqrt(1.0 - nx * nx - ny * ny)])
    return PATENT[0:3] * 1e-3, n, PATENT[5:8] * 1e-3


# ----------------------------------------------------------------------------- plain numpy truth


def rodrigues(axis, angle: float) -> np.ndarray:
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def rotation_taking(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation with ``R a = b`` (unit vectors)."""
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(a @ b)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        return rodrigues(np.cross(a, np.eye(3)[np.argmin(np.abs(a))]), math.pi)
    return rodrigues(axis, math.atan2(s, c))


def tilting_scan(rng, count: int, origin, direction, centre, *, radius: float = RADIUS,
                 noise: float = NOISE, max_tilt_deg: float = 30.0, spin_deg: float = 90.0,
                 translate_only: bool = False, beam_axis=(0.0, 0.0, -1.0)):
    """Flange poses (N x 4 x 4) [m], noisy distances (N,) [m] and ``cos`` of incidence.

    The beam (base frame) tilts up to ``max_tilt_deg`` about ``beam_axis`` and spins up
    to ``spin_deg`` about itself; it hits the sphere within 40 deg of the point facing it;
    the raw distance lies in [-20, 20] mm about the laser reference point.
    """
    beam_axis = np.asarray(beam_axis, float) / np.linalg.norm(beam_axis)
    lift = rotation_taking(np.array([0.0, 0.0, -1.0]), beam_axis)
    fixed = rotation_taking(direction, beam_axis)
    poses = np.tile(np.eye(4), (count, 1, 1))
    distance, incidence = np.empty(count), np.empty(count)
    for i in range(count):
        if translate_only:
            R = fixed
        else:
            tilt = math.radians(max_tilt_deg) * math.sqrt(rng.uniform())
            azimuth = rng.uniform(0, 2 * math.pi)
            local = np.array([math.sin(tilt) * math.cos(azimuth),
                              math.sin(tilt) * math.sin(azimuth), -math.cos(tilt)])
            d = lift @ local
            R = rodrigues(d, math.radians(rng.uniform(-spin_deg, spin_deg))) \
                @ rotation_taking(direction, d)
        d = R @ direction
        while True:  # the hit point's outward normal, facing the beam
            m = rng.normal(size=3)
            m /= np.linalg.norm(m)
            if -m @ d > math.cos(math.radians(40.0)):
                break
        surface = centre + radius * m
        length = rng.uniform(-0.02, 0.02)
        reference = surface - length * d
        poses[i, :3, :3] = R
        poses[i, :3, 3] = reference - R @ origin
        distance[i], incidence[i] = length, d @ m
    return poses, distance + rng.normal(0.0, noise, count), incidence


def noise_floor(incidence: np.ndarray, noise: float = NOISE, unknowns: int = 8) -> float:
    """Expected residual RMS [m]: distance noise seen along the surface normal."""
    count = len(incidence)
    return noise * math.sqrt(np.mean(incidence ** 2) * (count - unknowns) / count)


def quaternion_wxyz(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


def write_pendant_dataset(folder: Path, poses, distance, *, radius=RADIUS, extra_rows=None,
                          laser=None) -> Path:
    """A sphere_laser dataset (mm, deg) with pendant poses; ``extra_rows`` edit cells."""
    folder.mkdir(parents=True, exist_ok=True)
    save_robot(examples.industrial_6r(), folder / "robot.yaml")
    rows = []
    for T, length in zip(poses, distance):
        q = quaternion_wxyz(T[:3, :3])
        rows.append([repr(float(v)) for v in (*(T[:3, 3] * 1e3), *q, length * 1e3)])
    for index, column, text in extra_rows or ():
        rows[index][column] = text
    lines = ["x,y,z,qw,qx,qy,qz,distance"] + [",".join(r) for r in rows]
    (folder / "scan.csv").write_text("\n".join(lines) + "\n")
    content = {"kind": "sphere_laser", "robot": "robot.yaml",
               "units": {"length": "mm", "angle": "deg"}, "sphere": {"radius": radius * 1e3},
               "data": "scan.csv"}
    if laser:
        content["laser"] = laser
    (folder / "scan.yaml").write_text(yaml.safe_dump(content))
    return folder / "scan.yaml"


# ----------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def patent_scan():
    rng = np.random.default_rng(0)
    p0, n, c = patent_truth()
    poses, distance, incidence = tilting_scan(rng, 820, p0, n, c)
    return poses, distance, incidence


# ---------------------------------------------------------------------- residual and Jacobian


def test_residuals_match_a_plain_loop(patent_scan):
    poses, distance, _ = patent_scan
    p0, n, c = patent_truth()
    expected = [np.linalg.norm(T[:3, :3] @ (p0 + length * n) + T[:3, 3] - c) - RADIUS
                for T, length in zip(poses[:50], distance[:50])]
    got = surface_residuals(poses[:50], distance[:50], RADIUS, p0, n, c)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-15)


@pytest.mark.parametrize("direction", [(0, 0, 1), (1, 0, 0), (0, -1, 0), (0.3, -0.5, -0.8)])
def test_jacobian_matches_finite_differences(patent_scan, direction):
    poses, distance, _ = patent_scan
    poses, distance = poses[:40], distance[:40]
    n = np.asarray(direction, float) / np.linalg.norm(direction)
    p0, c = np.array([0.05, -0.02, 0.13]), np.array([-0.1, -0.3, 0.1])
    E = tangent_basis(n)
    scan = Scan.from_poses(poses, distance, RADIUS)
    _, J = scan.residual_and_jacobian(p0, n, c, E)

    def residual(delta):
        moved = n + E @ delta[3:5]
        return surface_residuals(poses, distance, RADIUS, p0 + delta[0:3],
                                 moved / np.linalg.norm(moved), c + delta[5:8])

    h = 1e-6
    numeric = np.column_stack([(residual(h * e) - residual(-h * e)) / (2 * h) for e in np.eye(8)])
    np.testing.assert_allclose(J, numeric, rtol=0, atol=1e-8)


def test_tangent_basis_is_orthonormal_for_any_direction():
    rng = np.random.default_rng(3)
    for n in [*np.eye(3), *(-np.eye(3)), *rng.normal(size=(20, 3))]:
        n = n / np.linalg.norm(n)
        frame = np.column_stack([tangent_basis(n), n])
        np.testing.assert_allclose(frame.T @ frame, np.eye(3), atol=1e-14)
        assert np.linalg.det(frame) == pytest.approx(1.0)


def test_algebraic_start_is_exact_without_noise():
    rng = np.random.default_rng(5)
    p0, n, c = patent_truth()
    poses, distance, _ = tilting_scan(rng, 200, p0, n, c, noise=0.0)
    origin, direction, centre = algebraic_start(Scan.from_poses(poses, distance, RADIUS))
    np.testing.assert_allclose(origin, p0, atol=1e-9)
    np.testing.assert_allclose(direction, n, atol=1e-9)
    np.testing.assert_allclose(centre, c, atol=1e-9)


# ----------------------------------------------------------------------------- the published case


@pytest.mark.parametrize("method", ["lm", "ipopt"])
def test_patent_case_recovered_within_three_std(patent_scan, method):
    poses, distance, incidence = patent_scan
    p0, n, c = patent_truth()
    fit = fit_sensor(poses, distance, RADIUS, method=method)
    truth = np.concatenate([p0, n, c])
    estimate = np.concatenate([fit.origin, fit.direction, fit.centre])
    std = np.concatenate([fit.origin_std, fit.direction_std, fit.centre_std])
    assert np.all(np.abs(estimate - truth) <= 3 * std), (estimate - truth) / std
    assert np.all(std[[0, 1, 2, 6, 7, 8]] < 5e-6)  # a few micrometres: the data do pin it
    floor = noise_floor(incidence)
    assert abs(fit.residual_rms - floor) <= 0.1 * floor
    assert np.linalg.norm(fit.direction) == pytest.approx(1.0, abs=1e-14)
    assert fit.patent_vector().shape == (8,)
    assert fit.status in ("converged", "Solve_Succeeded", "Solved_To_Acceptable_Level",
                          "Search_Direction_Becomes_Too_Small")


def test_noise_free_readings_converge_exactly():
    """Planned (noise-free) readings: an exact fit ends at once, not at max_iterations."""
    p0, n, c = patent_truth()
    poses, distance, _ = tilting_scan(np.random.default_rng(0), 60, p0, n, c, noise=0.0)
    fit = fit_sensor(poses, distance, RADIUS)
    assert fit.status == "converged" and fit.iterations < 20
    assert fit.residual_rms < 1e-13
    np.testing.assert_allclose(np.concatenate([fit.origin, fit.direction, fit.centre]),
                               np.concatenate([p0, n, c]), atol=1e-12)


def test_lm_and_ipopt_reach_the_same_minimum(patent_scan):
    poses, distance, _ = patent_scan
    lm = fit_sensor(poses, distance, RADIUS, method="lm")
    ipopt = fit_sensor(poses, distance, RADIUS, method="ipopt")
    np.testing.assert_allclose(lm.origin, ipopt.origin, atol=1e-9)
    np.testing.assert_allclose(lm.direction, ipopt.direction, atol=1e-8)
    np.testing.assert_allclose(lm.centre, ipopt.centre, atol=1e-9)


def test_covariance_matches_the_spread_over_repeated_scans():
    """The reported std is the scatter of the estimate over independent noise draws."""
    p0, n, c = patent_truth()
    rng = np.random.default_rng(11)
    poses, clean, _ = tilting_scan(rng, 300, p0, n, c, noise=0.0)
    estimates, stds = [], []
    for _ in range(40):
        fit = fit_sensor(poses, clean + rng.normal(0, NOISE, len(clean)), RADIUS,
                         direction_guess=[0, 0, 1])
        estimates.append(np.concatenate([fit.origin, fit.centre]))
        stds.append(np.concatenate([fit.origin_std, fit.centre_std]))
    ratio = np.std(estimates, axis=0) / np.mean(stds, axis=0)
    assert np.all((ratio > 0.6) & (ratio < 1.5)), ratio


def test_sensor_fit_repr_reads_in_millimetres(patent_scan):
    poses, distance, _ = patent_scan
    text = repr(fit_sensor(poses, distance, RADIUS))
    assert text.startswith("SensorFit(origin=[61.2")
    assert "mm" in text and "residual_rms=" in text and "status=" in text


# ---------------------------------------------------------------------- any direction, no guess


@pytest.mark.parametrize("seed", range(8))
def test_any_beam_direction_without_guesses(seed):
    rng = np.random.default_rng(100 + seed)
    n = [*np.eye(3), *(-np.eye(3))][seed] if seed < 6 else rng.normal(size=3)
    n = n / np.linalg.norm(n)
    p0, c = rng.uniform(-0.2, 0.2, 3), rng.uniform(-0.8, 0.8, 3)
    radius = rng.uniform(0.01, 0.1)
    poses, distance, _ = tilting_scan(rng, 300, p0, n, c, radius=radius,
                                      beam_axis=rng.normal(size=3))
    fit = fit_sensor(poses, distance, radius)
    truth = np.concatenate([p0, n, c])
    estimate = np.concatenate([fit.origin, fit.direction, fit.centre])
    std = np.concatenate([fit.origin_std, fit.direction_std, fit.centre_std])
    assert np.all(np.abs(estimate - truth) <= 4 * std + 1e-12), (estimate - truth) / std


def test_a_wrong_guess_does_not_mislead():
    rng = np.random.default_rng(7)
    p0, n, c = patent_truth()
    poses, distance, _ = tilting_scan(rng, 200, p0, n, c)
    fit = fit_sensor(poses, distance, RADIUS, direction_guess=[0, 0, -1],
                     origin_guess=[0.0, 0.0, 0.0], centre_guess=[0.5, 0.5, 0.5])
    np.testing.assert_allclose(fit.origin, p0, atol=2e-5)
    np.testing.assert_allclose(fit.centre, c, atol=2e-5)


def test_fallback_starts_recover_when_the_closed_form_start_is_useless(monkeypatch):
    """Guesses, then the six flange axes, take over from a failed closed-form start."""
    import robocal_casadi.instruments.laser.sphere_fit as sphere_fit

    useless = (np.full(3, 5.0), np.array([1.0, 0.0, 0.0]), np.full(3, -5.0))
    monkeypatch.setattr(sphere_fit, "algebraic_start", lambda scan: useless)
    rng = np.random.default_rng(8)
    p0, n, c = patent_truth()
    poses, distance, _ = tilting_scan(rng, 300, p0, n, c)
    for guesses in ({}, {"direction_guess": [0.0, 0.1, 1.0], "origin_guess": [0.05, 0, 0.1]}):
        fit = fit_sensor(poses, distance, RADIUS, **guesses)
        np.testing.assert_allclose(fit.origin, p0, atol=4 * fit.origin_std.max())
        np.testing.assert_allclose(fit.centre, c, atol=4 * fit.centre_std.max())


# ----------------------------------------------------------------------------- identifiability


@pytest.mark.parametrize("method", ["lm", "ipopt"])
def test_pure_translation_scan_is_refused_with_the_numbers(method):
    rng = np.random.default_rng(1)
    p0, n, c = patent_truth()
    poses, distance, _ = tilting_scan(rng, 820, p0, n, c, translate_only=True)
    with pytest.raises(InputError) as caught:
        fit_sensor(poses, distance, RADIUS, method=method)
    message = str(caught.value)
    assert "\n" not in message
    assert "does not separate the laser origin from the sphere centre" in message
    assert "3 of 8 singular values" in message and "pure translation" in message
    assert "p0 + d and c + R*d fit equally" in message


def test_spin_about_the_beam_only_leaves_p0_along_n_free():
    rng = np.random.default_rng(2)
    p0, n, c = patent_truth()
    poses, distance, _ = tilting_scan(rng, 300, p0, n, c, max_tilt_deg=0.0, spin_deg=180.0)
    with pytest.raises(InputError) as caught:
        fit_sensor(poses, distance, RADIUS)
    message = str(caught.value)
    assert "1 of 8 singular values" in message
    assert "p0 + t*d and c + t*R*d fit equally" in message and "the beam direction n" in message
    numbers = message.split("d = [")[1].split("]")[0]
    d = np.array([float(v) for v in numbers.split(",")])
    assert abs(abs(d @ n) - 1.0) < 1e-3


def test_a_little_tilt_is_enough_and_shows_in_the_std():
    rng = np.random.default_rng(2)
    p0, n, c = patent_truth()
    poses, distance, _ = tilting_scan(rng, 300, p0, n, c, max_tilt_deg=2.0, spin_deg=180.0)
    fit = fit_sensor(poses, distance, RADIUS)
    wide = fit_sensor(*tilting_scan(rng, 300, p0, n, c)[:2], RADIUS)
    assert fit.origin_std[2] > 5 * wide.origin_std[2]  # p0 along the beam is the weak one
    assert abs(fit.origin[2] - p0[2]) <= 3 * fit.origin_std[2]


def test_too_few_readings_and_bad_arrays_are_input_errors():
    p0, n, c = patent_truth()
    poses, distance, _ = tilting_scan(np.random.default_rng(0), 7, p0, n, c)
    with pytest.raises(InputError, match="7 readings cannot determine"):
        fit_sensor(poses, distance, RADIUS)
    poses, distance, _ = tilting_scan(np.random.default_rng(0), 20, p0, n, c)
    distance[3] = np.nan
    with pytest.raises(InputError, match="NaN"):
        fit_sensor(poses, distance, RADIUS)
    with pytest.raises(InputError, match="radius must be positive"):
        fit_sensor(poses, np.zeros(20), -1.0)


# ----------------------------------------------------------------------------- dataset files


def test_pendant_dataset_fit_and_model(tmp_path, patent_scan):
    poses, distance, _ = patent_scan
    path = write_pendant_dataset(tmp_path, poses, distance)
    dataset = load_dataset(path)
    p0, n, c = patent_truth()
    fit = fit_dataset(dataset)
    np.testing.assert_allclose(fit.origin, p0, atol=5 * fit.origin_std.max())

    model = INSTRUMENTS["sphere_laser"].model(dataset, "scan")
    assert isinstance(model, SphereLaserModel) and not model.uses_robot
    assert model.mounted.names == ("laser_x", "laser_y", "laser_z", "laser_nx", "laser_ny",
                                   "laser_nz")
    assert model.placement.names == ("scan/sphere_x", "scan/sphere_y", "scan/sphere_z")
    mounted = model.initial_mounted()
    np.testing.assert_allclose(mounted, np.concatenate([fit.origin, fit.direction]))

    def no_robot(offsets):
        raise AssertionError("pendant data must not ask the robot for points")

    centre = model.initial_placement(no_robot, mounted)
    np.testing.assert_allclose(centre, fit.centre, atol=1e-7)

    # the CasADi residual against plain numpy, and the gauge row
    x = ca.MX.sym("x", 9)
    r = ca.Function("r", [x], [model.residual(no_robot, x[0:6], x[6:9])])
    v = 1.5 * n  # a non-unit v: the model normalises, the gauge row reports |v| - 1
    values = np.asarray(r(np.concatenate([p0, v, c]))).ravel()
    assert len(values) == model.residual_size() == len(distance) + 1
    np.testing.assert_allclose(values[:-1], surface_residuals(poses, distance, RADIUS, p0, n, c),
                               atol=1e-12)
    assert values[-1] == pytest.approx(0.5)
    np.testing.assert_allclose(model.errors(values), np.abs(values[:-1]))
    np.testing.assert_array_equal(model.error_rows(), np.arange(len(distance)))


def test_consistent_dataset_puts_every_point_on_the_sphere(tmp_path, patent_scan):
    poses, distance, _ = patent_scan
    dataset = load_dataset(write_pendant_dataset(tmp_path, poses[:100], distance[:100]))
    model = SphereLaserModel(dataset, "scan")
    p0, n, c = patent_truth()
    consistent = model.consistent_dataset(None, None, np.concatenate([p0, n]), c)
    residual = surface_residuals(poses[:100], consistent.distance, RADIUS, p0, n, c)
    assert np.max(np.abs(residual)) < 1e-12
    assert np.max(np.abs(consistent.distance - distance[:100])) < 10 * NOISE


def test_degenerate_pendant_file_names_the_table(tmp_path):
    rng = np.random.default_rng(1)
    p0, n, c = patent_truth()
    poses, distance, _ = tilting_scan(rng, 100, p0, n, c, translate_only=True)
    dataset = load_dataset(write_pendant_dataset(tmp_path, poses, distance))
    with pytest.raises(InputError) as caught:
        SphereLaserModel(dataset, "scan").initial_mounted()
    assert str(caught.value).startswith(str(tmp_path / "scan.csv") + ": scan: the scan does not")


@pytest.mark.parametrize("column, text, expected", [
    (7, "", "line 5: column 'distance': expected a number, got ''"),
    (7, "nan", "line 5: column 'distance': expected a finite number, got 'nan'"),
    (3, "nan", "line 5: column 'qw': expected a finite number, got 'nan'"),
    (4, "0.5", "line 5: quaternion (qw, qx, qy, qz) has norm"),
])
def test_bad_rows_are_refused_by_name(tmp_path, patent_scan, column, text, expected):
    poses, distance, _ = patent_scan
    path = write_pendant_dataset(tmp_path, poses[:20], distance[:20],
                                 extra_rows=[(3, column, text)])
    with pytest.raises(InputError) as caught:
        load_dataset(path)
    assert "scan.csv" in str(caught.value) and expected in str(caught.value)


def test_quaternion_off_unit_by_more_than_1e_6_is_refused(tmp_path, patent_scan):
    poses, distance, _ = patent_scan
    path = write_pendant_dataset(tmp_path, poses[:20], distance[:20])
    lines = (tmp_path / "scan.csv").read_text().splitlines()
    cells = lines[6].split(",")
    for k in range(3, 7):  # the quaternion scaled: its norm is 1 + 2e-6
        cells[k] = repr(float(cells[k]) * (1 + 2e-6))
    lines[6] = ",".join(cells)
    (tmp_path / "scan.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match="line 7: quaternion"):
        load_dataset(path)


def test_missing_distance_column_is_named(tmp_path, patent_scan):
    poses, distance, _ = patent_scan
    path = write_pendant_dataset(tmp_path, poses[:20], distance[:20])
    lines = (tmp_path / "scan.csv").read_text().splitlines()
    (tmp_path / "scan.csv").write_text("\n".join(line.rsplit(",", 1)[0] for line in lines))
    with pytest.raises(InputError, match="scan.csv: line 1: missing column 'distance'"):
        load_dataset(path)


# ----------------------------------------------------------------------------- robot plus sensor


def dh_link(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """Standard DH ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``, written out by hand."""
    ct, st, ca_, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([[ct, -st * ca_, st * sa, a * ct], [st, ct * ca_, -ct * sa, a * st],
                     [0.0, sa, ca_, d], [0.0, 0.0, 0.0, 1.0]])


def flange_of(table, q) -> np.ndarray:
    T = np.eye(4)
    for (theta, d, a, alpha), reading in zip(table, q):
        T = T @ dh_link(theta + reading, d, a, alpha)
    return T


def joints_reaching(table, target: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Joint values putting the flange at ``target`` (damped Newton, numeric Jacobian)."""

    def error(q):
        T = flange_of(table, q)
        R = T[:3, :3].T @ target[:3, :3]
        w = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
        return np.concatenate([target[:3, 3] - T[:3, 3], T[:3, :3] @ w])

    q = start.copy()
    for _ in range(40):
        e = error(q)
        if np.linalg.norm(e) < 1e-12:
            break
        J = np.column_stack([(error(q + h) - e) / 1e-7 for h in 1e-7 * np.eye(len(q))])
        step = np.linalg.lstsq(J, e, rcond=None)[0]
        q = q - step * min(1.0, 0.3 / np.abs(step).max())
    return q


# Errors of the true robot: lengths and angles the sphere data identify (no pair of them
# dependent, nothing on joint 6, whose errors the laser's own unknowns absorb). One sphere
# seen from a small patch of the workspace leaves theta2, a2, alpha2 and alpha3 with less
# than 1% of their effect their own: the 1% rule holds them at nominal, the prior rule
# estimates them against their tolerances (checked below).
TRUE_ERRORS = ("a1", "alpha1", "theta3", "a3", "theta4", "d4", "a4", "alpha4", "theta5", "d5",
               "a5", "alpha5")
WEAK = ("theta2", "a2", "alpha2", "alpha3")


def joint_scan(folder: Path, rng, count: int = 300):
    """A joint-reading sphere_laser dataset of ``industrial_6r`` from a perturbed truth.

    Returns the dataset path, the truth (robot parameters by name [SI], ``p0``, ``n``,
    ``c``) and the cosines of incidence. Flange targets tilt up to 25 deg about a home
    pose and spin up to 60 deg about the beam; the readings are the distances where the
    TRUE robot's beam meets the sphere (ray-sphere intersection), plus noise.
    """
    robot = examples.industrial_6r()
    names = ("theta", "d", "a", "alpha")
    truth = {f"{k}{i}": getattr(j, k) for i, j in enumerate(robot.joints, 1) for k in names}
    for name in TRUE_ERRORS:
        truth[name] += rng.normal(0, 0.5e-3) if name[0] in "ad" and not name.startswith(
            "alpha") else rng.normal(0, math.radians(0.05))
    table = [tuple(truth[f"{k}{i}"] for k in names) for i in range(1, 7)]
    p0, n, _ = patent_truth()
    home = np.radians([10, -30, 20, 0, 60, 0])
    T = flange_of(table, home)
    beam = T[:3, :3] @ n
    centre = T[:3, :3] @ p0 + T[:3, 3] + RADIUS * beam
    Q, distance, incidence = np.empty((count, 6)), np.empty(count), np.empty(count)
    for i in range(count):
        tilt = rodrigues(np.cross(beam, rng.normal(size=3)),
                         math.radians(25) * math.sqrt(rng.uniform()))
        R = tilt @ T[:3, :3] @ rodrigues(n, math.radians(rng.uniform(-60, 60)))
        d = R @ n
        while True:
            m = rng.normal(size=3)
            m /= np.linalg.norm(m)
            if -m @ d > math.cos(math.radians(40.0)):
                break
        target = np.eye(4)
        target[:3, :3] = R
        target[:3, 3] = centre + RADIUS * m - rng.uniform(-0.02, 0.02) * d - R @ p0
        Q[i] = joints_reaching(table, target, home)
        F = flange_of(table, Q[i])  # the reading comes from the true robot at these joints
        w = F[:3, :3] @ p0 + F[:3, 3] - centre
        along = (F[:3, :3] @ n) @ w
        distance[i] = -along - math.sqrt(along ** 2 - w @ w + RADIUS ** 2)
        hit = w + distance[i] * (F[:3, :3] @ n)
        incidence[i] = (F[:3, :3] @ n) @ hit / RADIUS
    distance += rng.normal(0.0, NOISE, count)
    folder.mkdir(parents=True, exist_ok=True)
    save_robot(robot, folder / "robot.yaml")
    lines = ["q1,q2,q3,q4,q5,q6,distance"] + [
        ",".join(repr(float(v)) for v in (*np.degrees(q), length * 1e3))
        for q, length in zip(Q, distance)]
    (folder / "scan.csv").write_text("\n".join(lines) + "\n")
    (folder / "scan.yaml").write_text(yaml.safe_dump({
        "kind": "sphere_laser", "robot": "robot.yaml", "units": {"length": "mm", "angle": "deg"},
        "sphere": {"radius": RADIUS * 1e3}, "data": "scan.csv"}))
    return folder / "scan.yaml", truth, p0, n, centre, incidence


def test_robot_and_sensor_recovered_together_by_calibrate(tmp_path):
    from robocal_casadi.calibration import calibrate

    path, truth, p0, n, centre, incidence = joint_scan(tmp_path, np.random.default_rng(4))
    dataset = load_dataset(path)
    model = SphereLaserModel(dataset, "scan")
    assert model.uses_robot
    strict = calibrate([dataset], diagnose=False, rule="fraction")
    for name in WEAK:
        assert "too little for these data" in strict.identifiability.unidentifiable[name]
    # Against their tolerances the weak ones are estimated too (and checked below).
    result = calibrate([dataset], diagnose=False, rule="prior")

    identified = {p.name: p for p in result.parameters if p.identifiable}
    assert set(TRUE_ERRORS) | set(WEAK) <= set(identified)
    z = {name: (p.estimate - truth.get(name, p.nominal)) / p.std for name, p in identified.items()}
    laser = np.concatenate([p0, n])
    for k, name in enumerate(("laser_x", "laser_y", "laser_z", "laser_nx", "laser_ny",
                              "laser_nz")):
        estimate, std = result.mounted[name]
        z[name] = (estimate - laser[k]) / std
    # About 20 estimates: with Gaussian errors one of them beyond 3 std happens one time
    # in twenty, two or one beyond 4 std almost never.
    beyond = [name for name, v in z.items() if abs(v) > 3]
    assert len(beyond) <= 1 and all(abs(v) <= 4 for v in z.values()), z
    found = np.array([result.placement[f"scan/sphere_{a}"] for a in "xyz"])
    # The centre moves with the weakest robot angle: three of alpha1's std over ~1 m.
    assert np.linalg.norm(found - centre) < 3 * identified["alpha1"].std * 1.0
    assert result.fit.rms_nominal > 10 * result.fit.rms_geometric
    floor = noise_floor(incidence, unknowns=result.solver["free_unknowns"])
    assert abs(result.fit.rms_geometric - floor) <= 0.1 * floor


def test_joint_model_jacobian_through_the_problem_matches_finite_differences(tmp_path):
    from robocal_casadi.calibration import Problem, models_for
    from robocal_casadi.model.kinematics import Kinematics

    path, truth, p0, n, centre, _ = joint_scan(tmp_path, np.random.default_rng(9), count=30)
    dataset = load_dataset(path)
    problem = Problem(dataset.robot, models_for([dataset]))
    x = problem.initial()
    x[problem.unknowns.indices(["laser_nx", "laser_ny", "laser_nz"])] *= 1.3  # off the gauge
    J = problem.jacobian(x)
    h = 1e-7
    numeric = np.column_stack([(problem.residual(x + h * e) - problem.residual(x - h * e))
                               / (2 * h) for e in np.eye(len(x))])
    np.testing.assert_allclose(J, numeric, rtol=1e-5, atol=1e-7)
    assert problem.residual(x)[-1] == pytest.approx(0.3, abs=1e-12)  # the |v| = 1 row

    # consistent data: the beam of every reading ends on the sphere for these unknowns
    model = problem.models[0]
    mounted = x[problem.mounted_indices(model)]
    placement = x[problem.placement_indices(model)]
    kinematics = Kinematics(dataset.robot)
    consistent = model.consistent_dataset(kinematics, kinematics.nominal, mounted, placement)
    poses = kinematics.flange_poses(dataset.joints)
    origin, direction = mounted[:3], mounted[3:] / np.linalg.norm(mounted[3:])
    residual = surface_residuals(poses, consistent.distance, RADIUS, origin, direction, placement)
    assert np.max(np.abs(residual)) < 1e-12
