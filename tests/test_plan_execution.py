"""Plans a robot can run: capsule distances against brute force, realistic joint ranges,
collision and line-of-sight checks, run order, the predicted tool error against a
Monte-Carlo simulation, laser scans (constraints checked independently, the laser
identified on a simulated truth) and controller programs."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from planning import design_plan
from planning.collision import Body, segment_distance, segment_distances
from planning.order import largest_moves, nearest_turns, open_path
from planning.ranges import ELBOW_LIMIT, elbows, working_ranges
from robocal_casadi.cli import main
from robocal_casadi.common.table import read_table
from robocal_casadi.errors import InputError
from robocal_casadi.instruments import instrument
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.instruments.laser.sphere_fit import fit_sensor
from robocal_casadi.model.examples import industrial_6r, panda_7dof, ur_type
from robocal_casadi.model.kinematics import Kinematics
from robocal_casadi.model.robot import save_robot

# ----------------------------------------------------------------------------- geometry


def _brute_distance(P0, P1, Q0, Q1, steps=801):
    s = np.linspace(0, 1, steps)
    A = P0 + s[:, None] * (P1 - P0)
    B = Q0 + s[:, None] * (Q1 - Q0)
    return np.min(np.linalg.norm(A[:, None] - B[None], axis=2))


def test_segment_distance_matches_brute_force_including_parallel_and_points():
    rng = np.random.default_rng(0)
    cases = [rng.normal(size=(4, 3)) for _ in range(30)]
    d = np.array([1.0, 0.5, 0.0])
    cases.append(np.array([[0, 0, 0], d, [0.2, 0.3, 0], d + [0.2, 0.3, 0]]))  # parallel
    cases.append(np.array([[0, 0, 0], [0, 0, 0], [1.0, 1, 1], [2.0, 1, 1]]))  # a point
    for P0, P1, Q0, Q1 in cases:
        exact = segment_distances(P0, P1, Q0, Q1)
        assert exact == pytest.approx(_brute_distance(P0, P1, Q0, Q1), abs=2e-3)
        assert exact <= _brute_distance(P0, P1, Q0, Q1) + 1e-12


def test_symbolic_segment_distance_and_clearances_agree_with_the_numeric_check():
    import casadi as ca

    rng = np.random.default_rng(3)
    P = ca.SX.sym("P", 3, 4)
    f = ca.Function("d", [P], [segment_distance(P[:, 0], P[:, 1], P[:, 2], P[:, 3])])
    for _ in range(40):
        X = rng.normal(size=(4, 3))
        assert float(f(X.T)) == pytest.approx(float(segment_distances(*X)), abs=1e-12)
    kin = Kinematics(working_ranges(ur_type()))
    body = Body(kin, [0, 0, 0.1], 0.0)
    q = ca.SX.sym("q", kin.dof)
    gaps = ca.Function("g", [q], [body.clearances(q)])
    Q = np.vstack([kin.robot.lower_limits + rng.uniform(size=(400, kin.dof))
                   * (kin.robot.upper_limits - kin.robot.lower_limits),
                   np.radians([[0, -90, 175, -90, -90, 0], [0, 30, 0, 0, 0, 0]])])
    checked = body.check(Q)
    smallest = np.array([np.asarray(gaps(x)).min() for x in Q])
    # clear in both exactly where every gap is non-negative (up to the check's 1e-9)
    assert np.array_equal(smallest >= -1e-9, checked.table & checked.self)
    assert (smallest < 0).any() and (smallest > 0).any()


def test_working_ranges_limit_the_elbow_and_fill_missing_limits():
    ur = ur_type()
    assert elbows(ur) == [2]  # between the two long links
    ranged = working_ranges(ur)
    assert ranged.joints[2].limits == pytest.approx((-ELBOW_LIMIT, ELBOW_LIMIT))
    for k in (0, 1, 3, 4, 5):  # the others keep the controller's +-360 deg, less 5 deg
        assert ranged.joints[k].limits == pytest.approx(
            (ur.joints[k].limits[0] + math.radians(5), ur.joints[k].limits[1] - math.radians(5)))
    from dataclasses import replace
    bare = replace(ur, joints=tuple(replace(j, limits=None) for j in ur.joints))
    assert all(j.limits is not None and j.limits[1] == pytest.approx(math.radians(175))
               for j in working_ranges(bare).joints)
    r6 = industrial_6r()  # narrower limits stay as they are, less their margin
    for ranged_joint, joint in zip(working_ranges(r6).joints, r6.joints):
        lo, hi = joint.limits
        margin = min(0.05 * (hi - lo), math.radians(5))
        assert ranged_joint.limits == pytest.approx((lo + margin, hi - margin))


def test_capsules_catch_a_folded_elbow_the_table_and_a_blocked_line_of_sight():
    kin = Kinematics(working_ranges(ur_type()))
    body = Body(kin, [0, 0, 0.1], 0.0)
    q = np.radians
    upright = q([0, -90, 90, -90, -90, 0])
    assert body.check(upright[None]).clear[0]
    folded = q([0, -90, 175, -90, -90, 0])
    assert not body.check(folded[None]).self[0]
    down = q([0, 30, 0, 0, 0, 0])  # upper arm driven below the base
    assert not body.check(down[None]).table[0]
    # an instrument straight behind the upper arm (it rises along z from the shoulder)
    points = body.points(upright[None])[0]
    shoulder, elbow = points[body.segments[1, 0]], points[body.segments[1, 1]]
    target = points[-1]
    middle = 0.5 * (shoulder + elbow)
    behind = target + 3.0 * (middle - target)  # the line target -> instrument crosses the arm
    seen = Body(kin, [0, 0, 0.1], 0.0, instrument=behind)
    assert not seen.check(upright[None]).sight[0]
    outward = (target - points[-2]) / np.linalg.norm(target - points[-2])  # along the tool
    clear_view = Body(kin, [0, 0, 0.1], 0.0, instrument=target + 3.0 * outward)
    assert clear_view.check(upright[None]).sight[0]


# ----------------------------------------------------------------------------- order


def test_open_path_is_never_longer_than_a_random_order_and_turns_keep_poses():
    rng = np.random.default_rng(1)
    X = rng.uniform(-3, 3, (25, 6))
    C = np.max(np.abs(X[:, None] - X[None]), axis=2)
    path = open_path(C)
    assert sorted(path) == list(range(25))
    length = np.sum(C[path[:-1], path[1:]])
    randoms = [np.sum(C[p[:-1], p[1:]]) for p in (rng.permutation(25) for _ in range(50))]
    assert length < min(randoms)
    # a joint with +-360 deg takes the turn nearest the previous pose; the pose is the same
    robot = ur_type()
    Q = rng.uniform(-np.pi, np.pi, (10, 6))
    Q[:, 3] += 2 * np.pi * (rng.random(10) > 0.5)
    turned = nearest_turns(Q, robot.lower_limits, robot.upper_limits)
    kin = Kinematics(robot)
    assert np.allclose(kin.flange_poses(turned), kin.flange_poses(Q), atol=1e-12)
    assert np.sum(largest_moves(turned)) <= np.sum(largest_moves(Q)) + 1e-12


# ----------------------------------------------------------------------------- plans


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("run")
    save_robot(ur_type(), folder / "ur.yaml")
    save_robot(industrial_6r(), folder / "r6.yaml")
    save_robot(panda_7dof(), folder / "p7.yaml")
    mm = dict(length="mm", angle="deg")
    content = {
        "tracker_ur": dict(kind="tracker_points", robot="ur.yaml", units=mm,
                           target=dict(xyz=[0, 0, 100]), instrument=dict(xyz=[2500, 0, 800])),
        "bar_ur": dict(kind="cross_bar", robot="ur.yaml", units=mm, bar=dict(length=300),
                       probe=dict(xyz=[0, 0, 150])),
        "tracker_7": dict(kind="tracker_points", robot="p7.yaml", units=dict(length="m",
                          angle="rad"), target=dict(xyz=[0, 0, 0.1])),
        "sphere_6r": dict(kind="sphere_laser", robot="r6.yaml", units=mm,
                          sphere=dict(radius=25, centre_guess=[900, 100, 300]),
                          laser=dict(origin_guess=[60, -15, 140], direction_guess=[0, 0, 1]),
                          planning=dict(laser_rate=20)),
    }
    paths = {}
    for name, value in content.items():
        value["data"] = f"{name}.csv"
        paths[name] = folder / f"{name}.yaml"
        paths[name].write_text(yaml.safe_dump(value))
    return paths


@pytest.mark.parametrize("name", ["tracker_ur", "bar_ur"])
def test_plans_respect_ranges_capsules_and_are_ordered(files, name):
    dataset = load_dataset(files[name], require_data=False)
    plan = design_plan(dataset, 24 if name == "tracker_ur" else 10, seed=0, pool=60,
                       refine=False, quiet=True)
    Q = plan.joints
    assert np.all(np.abs(Q[:, 2]) <= ELBOW_LIMIT + 1e-9)  # the elbow, not the +-360 deg
    robot = working_ranges(dataset.robot)
    assert np.all(Q >= robot.lower_limits) and np.all(Q <= robot.upper_limits)
    kin = Kinematics(robot)
    offset = dataset.target if name == "tracker_ur" else dataset.probe
    body = Body(kin, offset, float(robot.base.xyz[2]),
                getattr(dataset, "instrument", None))
    assert body.check(Q).clear.all()
    assert plan.travel is not None
    assert np.sum(plan.travel.after) < np.sum(plan.travel.before)
    assert np.allclose(largest_moves(Q), plan.travel.after)
    if name == "bar_ur":  # the touches of one placement stay together
        poses = plan.poses
        assert all(np.all(np.diff(poses) >= 0) for _ in [0])
        probe = kin.points(Q, dataset.probe)
        sockets = np.array([c.sockets[p] for c in plan.candidates for p in c.points])
        assert np.max(np.linalg.norm(probe - sockets, axis=1)) < 1e-6
    assert 0 < plan.tool_error < np.inf and np.isfinite(plan.condition_all)


def test_predicted_tool_error_matches_a_monte_carlo_of_the_linear_fit(files):
    """``tool_error`` against repeated noisy least-squares fits of the plan's Jacobian,
    with the tool position error of each fit averaged over the same weights."""
    from planning.accuracy import tool_weights
    from planning.information import Information
    from planning.reach import Workspace
    from planning.rows import RowModel

    dataset = load_dataset(files["tracker_7"], require_data=False)
    plan = design_plan(dataset, 20, seed=0, pool=60, refine=False, quiet=True)
    kin = Kinematics(plan.setup.robot)
    rows = RowModel(plan.setup, kin)
    workspace = Workspace(kin, body=Body.of(plan.setup, kin))
    W = tool_weights(plan.setup, workspace, rows.parameters, np.random.default_rng(0))
    blocks = rows.blocks(list(plan.candidates))
    info = Information(blocks, rows.parameters, rows.shared, W)
    X = np.vstack([info.restrict(b) for b in blocks])
    Wi = W[np.ix_(info.identifiable, info.identifiable)]
    sigma = plan.setup.noise
    rng = np.random.default_rng(3)
    squares = []
    for _ in range(400):
        estimate, *_ = np.linalg.lstsq(X, rng.normal(0, sigma, len(X)), rcond=None)
        theta = estimate[:info.m]
        squares.append(theta @ Wi @ theta)
    from planning.accuracy import tool_error
    predicted = tool_error(info.spectrum_of([X], "tool"), sigma)
    assert math.sqrt(np.mean(squares)) == pytest.approx(predicted, rel=0.1)


def test_tool_weights_measure_the_point_error_left_after_the_best_rigid_motion(files):
    """``d^T W d`` against finite parameter steps: the robot's points at the perturbed
    parameters, registered rigidly (Kabsch) onto the nominal ones, mean squared error."""
    from planning.accuracy import tool_weights, workspace_samples
    from planning.reach import Workspace
    from planning.rows import RowModel
    from planning.setup import setup_from_dataset
    from robocal_casadi.instruments.tracker.model import rigid_registration

    setup = setup_from_dataset(load_dataset(files["bar_ur"], require_data=False))
    kin = Kinematics(setup.robot)
    workspace = Workspace(kin)
    names = RowModel(setup, kin).parameters
    W = tool_weights(setup, workspace, names, np.random.default_rng(4))
    Q = workspace_samples(setup, workspace, np.random.default_rng(4))
    nominal = kin.points(Q, setup.offset, workspace.p)
    rng = np.random.default_rng(8)
    n_robot = len(kin.registry)
    for _ in range(5):
        step = rng.normal(0, 1e-6, len(names))  # [m, rad]: small, so the model is linear
        moved = kin.points(Q, setup.offset + step[n_robot:], workspace.p + step[:n_robot])
        R, t = rigid_registration(moved, nominal)
        left = np.mean(np.sum((moved @ R.T + t - nominal) ** 2, axis=1))
        assert step @ W @ step == pytest.approx(left, rel=1e-3)
        whole = np.mean(np.sum((moved - nominal) ** 2, axis=1))
        assert left < 0.9 * whole  # the rigid part is not counted


# ----------------------------------------------------------------------------- scans


def _beam_hits(setup, poses):
    o = poses[:, :3, :3] @ setup.offset + poses[:, :3, 3]
    d = poses[:, :3, :3] @ (setup.axis / np.linalg.norm(setup.axis))
    v = o - setup.centre
    b = np.einsum("ni,ni->n", d, v)
    disc = b**2 - (np.einsum("ni,ni->n", v, v) - setup.radius**2)
    return d, o, b, disc


def test_sensor_only_scan_is_runnable_and_identifies_the_laser(files, tmp_path):
    from planning.trajectory import design_scan

    dataset = load_dataset(files["sphere_6r"], require_data=False)
    scan = design_scan(dataset, 120, seed=0, sensor_only=True, quiet=True, max_iterations=60)
    setup = scan.setup
    assert np.allclose(np.diff(scan.times), 1 / 20.0)
    # constraints, checked here from the poses alone
    d, o, b, disc = _beam_hits(setup, scan.flange_poses)
    assert np.all(disc > 0)
    reading = -b - np.sqrt(disc)
    assert np.all((reading >= 0.05 - 1e-7) & (reading <= 0.30 + 1e-7))
    hit = o + reading[:, None] * d
    normal = (hit - setup.centre) / setup.radius
    incidence = np.arccos(np.clip(-np.einsum("ni,ni->n", d, normal), -1, 1))
    assert np.all(incidence <= setup.max_incidence + 1e-6)
    speed = np.diff(scan.joints, axis=0) * 20.0
    assert np.all(np.abs(speed) <= setup.max_joint_speed * 1.001)
    assert scan.value <= scan.start_value
    # a simulated truth: laser and sphere off their guesses, readings with noise
    rng = np.random.default_rng(5)
    origin = setup.offset + rng.normal(0, 2e-3, 3)
    beam = setup.axis + rng.normal(0, 5e-3, 3)
    beam /= np.linalg.norm(beam)
    centre = setup.centre + rng.normal(0, 2e-3, 3)
    R, t = scan.flange_poses[:, :3, :3], scan.flange_poses[:, :3, 3]
    o_true = R @ origin + t
    d_true = R @ beam
    v = o_true - centre
    bb = np.einsum("ni,ni->n", d_true, v)
    dd = bb**2 - (np.einsum("ni,ni->n", v, v) - setup.radius**2)
    assert np.all(dd > 0)
    noise = setup.noise
    readings = -bb - np.sqrt(dd) + rng.normal(0, noise, len(dd))
    fit = fit_sensor(scan.flange_poses, readings, setup.radius, origin_guess=setup.offset,
                     direction_guess=setup.axis, centre_guess=setup.centre)
    assert fit.residual_rms < 1.5 * noise
    predicted = scan.laser_errors[:3]
    assert np.all(np.abs(fit.origin - origin) < 4 * np.maximum(predicted, fit.origin_std))
    # and as a whole within what the plan predicted: the length of a 3-vector of errors
    # with these standard deviations exceeds three times their norm with odds below 1%
    assert np.linalg.norm(fit.origin - origin) < 3 * np.linalg.norm(predicted)
    # the table: t first, pendant poses, distance empty
    out = tmp_path / "scan.csv"
    assert main(["plan", str(files["sphere_6r"]), "--count", "40", "--sensor-only", "--out",
                 str(out), "--urscript", str(tmp_path / "scan.script")]) == 0
    table = read_table(out)
    assert table.columns == ("t", "x", "y", "z", "qw", "qx", "qy", "qz", "distance")
    assert len(table) == 40 and all(c == "" for c in table.text("distance"))
    assert (tmp_path / "scan.script").read_text().count("servoj(") == 39


# ----------------------------------------------------------------------------- programs


def test_programs_list_the_poses_in_run_order(files, tmp_path):
    out = tmp_path / "plan.csv"
    assert main(["plan", str(files["tracker_ur"]), "--count", "20", "--no-refine", "--out",
                 str(out), "--urscript", str(tmp_path / "p.script"), "--krl",
                 str(tmp_path / "p.src")]) == 0
    table = read_table(out)
    Q = np.column_stack([table.numbers(f"q{i}") for i in range(1, 7)])
    script = (tmp_path / "p.script").read_text()
    moves = [line for line in script.splitlines() if line.strip().startswith("movej(")]
    assert len(moves) == 20
    first = np.array([float(v) for v in moves[0].split("[")[1].split("]")[0].split(",")])
    assert np.allclose(np.degrees(first), Q[0], atol=1e-4)
    krl_text = (tmp_path / "p.src").read_text()
    assert krl_text.startswith("DEF robocal_plan()") and krl_text.count("PTP {AXIS:") == 20
    assert f"A3 {Q[-1, 2]:.4f}" in krl_text


def test_programs_for_a_seven_axis_arm_are_refused_before_anything_is_written(files, tmp_path,
                                                                           capsys):
    out = tmp_path / "plan.csv"
    assert main(["plan", str(files["tracker_7"]), "--count", "20", "--no-refine", "--out",
                 str(out), "--urscript", str(tmp_path / "p.script")]) == 2
    assert "--urscript" in capsys.readouterr().err
    assert not out.exists() and not (tmp_path / "p.script").exists()


def _rapid_targets(text: str) -> tuple[np.ndarray, list[str]]:
    """The axis values [deg] of every ``MoveAbsJ`` of a RAPID module, and the moves' text
    after the target (speed, zone, tool), read with nothing of the writer."""
    axes, rest = [], []
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("MoveAbsJ [["):
            robax, _, after = line[len("MoveAbsJ [["):].partition("]")
            axes.append([float(v) for v in robax.split(",")])
            external = after.split("[", 1)[1].split("]", 1)[0]
            assert [v.strip() for v in external.split(",")] == ["9E9"] * 6
            rest.append(after.split("]]", 1)[1])
    return np.array(axes), rest


def test_a_rapid_program_moves_through_the_planned_poses_in_run_order(files, tmp_path):
    out = tmp_path / "plan.csv"
    assert main(["plan", str(files["tracker_ur"]), "--count", "20", "--no-refine", "--out",
                 str(out), "--rapid", str(tmp_path / "p.mod")]) == 0
    table = read_table(out)
    Q = np.column_stack([table.numbers(f"q{i}") for i in range(1, 7)])  # the file's deg
    text = (tmp_path / "p.mod").read_text()
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    assert lines[0] == "MODULE robocal_plan" and lines[-1] == "ENDMODULE"
    assert "PROC main()" in lines and lines[-2] == "ENDPROC"
    axes, rest = _rapid_targets(text)
    np.testing.assert_allclose(axes, Q, rtol=0, atol=0.5e-4)  # written with 4 decimals
    assert all(r == ", v100, fine, tool0;" for r in rest)
    assert text.count("WaitTime 0.5;") == 20


def test_a_rapid_scan_takes_the_planned_time_between_samples(files, tmp_path):
    out = tmp_path / "scan.csv"
    assert main(["plan", str(files["sphere_6r"]), "--count", "30", "--out", str(out),
                 "--rapid", str(tmp_path / "scan.mod")]) == 0
    table = read_table(out)
    t = table.numbers("t")
    Q = np.column_stack([table.numbers(f"q{i}") for i in range(1, 7)])
    axes, rest = _rapid_targets((tmp_path / "scan.mod").read_text())
    np.testing.assert_allclose(axes, Q, rtol=0, atol=0.5e-4)
    assert rest[0] == ", v100, fine, tool0;"  # go to the first sample and stop there
    durations = [float(r.split("\\T:=")[1].split(",")[0]) for r in rest[1:]]
    np.testing.assert_allclose(durations, np.diff(t), rtol=0, atol=0.5e-6)
    assert [r.rsplit(",", 2)[1].strip() for r in rest[1:]] == ["z0"] * 28 + ["fine"]


def test_a_rapid_program_for_a_seven_axis_arm_is_refused_before_anything_is_written(
        files, tmp_path, capsys):
    out = tmp_path / "plan.csv"
    assert main(["plan", str(files["tracker_7"]), "--count", "20", "--no-refine", "--out",
                 str(out), "--rapid", str(tmp_path / "p.mod")]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "--rapid" in error and "7 joints" in error
    assert not out.exists() and not (tmp_path / "p.mod").exists()


@pytest.mark.parametrize("index", ["tool", "O1"])
def test_scan_objective_is_the_index_of_the_sampled_readings(files, index):
    """The OCP minimises the index computed by the planner's own route (information.py):
    log(tool^2) = log sum 1 / s_i^2 of J L^-T, or -log det of the reference-scaled
    information = -2 m log O1."""
    from planning.trajectory import _ScanProblem, design_scan, spline_basis

    dataset = load_dataset(files["sphere_6r"], require_data=False)
    scan = design_scan(dataset, 60, seed=0, sensor_only=True, quiet=True, max_iterations=1)
    import planning.trajectory as trajectory

    captured = {}
    original = trajectory._ScanProblem.__init__

    def keep(self, setup, rows, info, *args, **kwargs):
        captured.update(rows=rows, info=info, setup=setup)
        original(self, setup, rows, info, *args, **kwargs)

    trajectory._ScanProblem.__init__ = keep
    try:
        design_scan(dataset, 60, seed=0, sensor_only=True, quiet=True, max_iterations=1)
    finally:
        trajectory._ScanProblem.__init__ = original
    rows, info, setup = captured["rows"], captured["info"], captured["setup"]
    duration = scan.times[-1]
    K = 12
    B, knots = spline_basis(scan.times, K, duration)
    C, *_ = np.linalg.lstsq(B, scan.joints, rcond=None)
    grid = np.arange(0, len(scan.times), 2)
    lower, upper = np.full(6, -10.0), np.full(6, 10.0)
    problem = _ScanProblem(setup, rows, info, index, B, grid, knots, lower, upper, 1)
    g = rows.evaluate(B[grid] @ C)[0]
    s = info.spectrum_of([g], "tool" if index == "tool" else "reference")
    expected = math.log(np.sum(1 / s**2)) if index == "tool" else -2 * np.sum(np.log(s))
    assert problem.objective(C) == pytest.approx(expected, rel=1e-4)  # a 1e-9 ridge


def test_scans_are_planned_for_the_kinds_whose_planner_scans(files):
    """``design_scan`` asks the kind's planner (``Planner.scans``): the laser's scans, the
    tracker's does not and a scan for it is refused, naming the file and key."""
    from planning.trajectory import design_scan

    assert instrument("sphere_laser").planner.scans
    assert not instrument("tracker_points").planner.scans
    dataset = load_dataset(files["tracker_ur"], require_data=False)
    with pytest.raises(InputError, match="scans are planned") as caught:
        design_scan(dataset, 120, quiet=True)
    assert Path(caught.value.file).name == "tracker_ur.yaml" and caught.value.where == "kind"


def test_the_laser_planner_predicts_accuracy_at_its_mid_range_reading(files):
    """The point whose accuracy a laser plan predicts lies on the nominal beam at the middle
    of the usable range, and the two directions it varies along are normal to the beam
    with that reading's length; other kinds predict at their measured point, unvaried."""
    from planning.accuracy import measured_point
    from planning.setup import setup_from_dataset

    laser = setup_from_dataset(load_dataset(files["sphere_6r"], require_data=False))
    point, t1, t2 = measured_point(laser)
    beam = point - laser.offset
    mid = 0.5 * (laser.laser_range[0] + laser.laser_range[1])
    axis = np.asarray(laser.axis, float) / np.linalg.norm(laser.axis)
    scale = 1e-12 * max(1.0, float(np.linalg.norm(point)))  # rounding of metre-sized sums
    np.testing.assert_allclose(np.linalg.norm(beam), mid, rtol=0, atol=scale)
    np.testing.assert_allclose(np.cross(beam, axis), 0.0, rtol=0, atol=scale)
    np.testing.assert_allclose([np.linalg.norm(t1), np.linalg.norm(t2)], mid, rtol=0,
                               atol=scale)
    np.testing.assert_allclose([t1 @ axis, t2 @ axis, t1 @ t2], 0.0, rtol=0, atol=scale)
    tracker = setup_from_dataset(load_dataset(files["tracker_ur"], require_data=False))
    point, t1, t2 = measured_point(tracker)
    np.testing.assert_array_equal(point, tracker.offset)
    assert not t1.any() and not t2.any()
