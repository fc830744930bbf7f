"""Tracking: the method's frame chain, the per-cycle NLP, and behaviour a controller trusts.

Independent references: the goal chain is worked out by hand here with plain numpy
(explicit matrices, no package transforms); joint answers are checked with the numpy
forward kinematics ``nominal_pose``; optimality (7-DOF redundancy, active limits) against
IPOPT on the same NLP. Targets are made reachable by construction: choose joints, take
their end pose, and write the camera observation that asks for it.
"""

from __future__ import annotations

import csv
import dataclasses
import math

import numpy as np
import pytest
import yaml

from robocal_casadi.cli import main
from robocal_casadi.common.units import Units
from robocal_casadi.errors import InputError
from robocal_casadi.model.examples import industrial_6r, panda_7dof, prismatic_rrp
from robocal_casadi.model.kinematics import nominal_pose
from robocal_casadi.model.robot import Joint, Robot, save_robot
from robocal_casadi.model.transforms import rpy_from_matrix
from robocal_casadi.tracking import R_B, Tracker, TrackingProblem
from robocal_casadi.tracking import observation_for as observation_for_pose

CAMERA = np.array([0.04, -0.03, 0.06])  # [m] camera origin in the end frame
STANDOFF = 0.25  # [m]
UP = np.array([0.0, 0.0, 1.0])


# ----------------------------------------------------------------------------- helpers


def rot(axis: str, angle: float) -> np.ndarray:
    """3x3 rotation written out by hand."""
    c, s = math.cos(angle), math.sin(angle)
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def pose(R: np.ndarray, p) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def observation_for(robot: Robot, q_capture, T_world_end_goal, camera=CAMERA,
                    standoff=STANDOFF) -> np.ndarray:
    """The observation whose facing pose ``A'`` is ``T_world_end_goal``: the target at
    ``T = A' Tz(Z) R_B`` seen from the end pose at ``q_capture``."""
    T_world_target = T_world_end_goal @ pose(R_B[:3, :3], [0, 0, standoff])
    B_C = np.linalg.inv(nominal_pose(robot, q_capture)) @ T_world_target
    xyz = B_C[:3, 3] - camera
    rpy = rpy_from_matrix(R_B[:3, :3].T @ B_C[:3, :3])
    return np.concatenate([xyz, rpy])


def level_pose(T: np.ndarray, up=UP) -> np.ndarray:
    """``T`` turned about its own z so that its x axis is perpendicular to ``up`` (the
    smaller turn), by solving ``cos(phi) u_x + sin(phi) u_y = 0`` with ``|phi| < pi/2``."""
    u_x, u_y = up @ T[:3, 0], up @ T[:3, 1]
    phi = math.atan(-u_x / u_y) if abs(u_y) > 1e-15 else math.copysign(math.pi / 2, -u_x)
    return T @ pose(rot("z", phi), [0, 0, 0])


def check_answer(robot: Robot, q, goal: np.ndarray, up=UP, tolerance=1e-9) -> None:
    """The answer meets the constraints, judged by numpy forward kinematics."""
    T = nominal_pose(robot, q)
    assert np.linalg.norm(T[:3, 3] - goal[:3, 3]) < tolerance
    assert np.linalg.norm(np.cross(T[:3, 2], goal[:3, 2])) < tolerance
    assert T[:3, 2] @ goal[:3, 2] > 0
    assert abs(up @ T[:3, 0]) < tolerance
    target_in_end = np.linalg.inv(T) @ goal @ np.array([0, 0, STANDOFF, 1.0])
    assert target_in_end[:3] == pytest.approx([0, 0, STANDOFF], abs=tolerance)
    assert np.all(q >= robot.lower_limits) and np.all(q <= robot.upper_limits)


def six_joint_robot() -> Robot:
    """A robot whose end pose at zero joints is ``Trans(0.5, 0, 1.0) Rx(180 deg)`` (tool
    pointing down at the table): joint 1 is ``Tz(1.0) Tx(0.5) Rx(pi)``, the others are
    identities."""
    joints = (Joint("revolute", 0.0, 1.0, 0.5, math.pi, limits=(-3.0, 3.0)),) + tuple(
        Joint("revolute", 0.0, 0.0, 0.0, 0.0, limits=(-3.0, 3.0)) for _ in range(5))
    return Robot("seed-case", "dh", joints, units=Units("m", "rad"))


@pytest.fixture(scope="module")
def trackers():
    """Shared problems (built once) per example robot."""
    return {name: TrackingProblem(make()) for name, make in
            (("industrial_6r", industrial_6r), ("panda_7dof", panda_7dof))}


# Start poses with the end z axis well away from the worktable normal (36 and 57 deg):
# as z nears ``up`` the level direction turns fast and so must the wrist.
START = {"industrial_6r": np.array([0.2, -0.4, 0.5, 0.3, 0.9, 0.2]),
         "panda_7dof": np.array([0.1, -0.3, 0.05, -2.0, 0.1, 2.7, 0.6])}


# ----------------------------------------------------------------------------- the seed chain


def test_fixed_rotation_is_rx90_then_rz90():
    by_hand = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0.0]])  # Rx(90) Rz(90) multiplied out
    assert R_B[:3, :3] == pytest.approx(by_hand, abs=1e-15)


def test_goal_pose_of_the_seed_case_by_hand():
    robot = six_joint_robot()
    camera = np.array([0.02, -0.01, 0.05])
    observation = np.array([0.01, 0.02, 0.30, 0.1, -0.2, 0.3])
    standoff = 0.25
    # By hand: A at zero joints, B from the camera, C = Rz(yaw) Ry(pitch) Rx(roll).
    A = pose(rot("x", math.pi), [0.5, 0.0, 1.0])
    R_target = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0.0]])
    B = pose(R_target, camera + observation[:3])
    C = pose(rot("z", 0.3) @ rot("y", -0.2) @ rot("x", 0.1), [0, 0, 0])
    T = A @ B @ C
    B_prime = pose(R_target, [0, 0, standoff])  # Tz(Z) R_B
    A_prime = T @ np.linalg.inv(B_prime)
    expected = level_pose(A_prime)

    tracker = Tracker(robot, camera, standoff)
    goal = tracker.goal(np.zeros(6), observation)
    assert goal == pytest.approx(expected, abs=1e-12)
    # What the goal means: the target at (0, 0, Z) in it, the z axis kept, x level.
    assert (np.linalg.inv(goal) @ T)[:3, 3] == pytest.approx([0, 0, standoff], abs=1e-12)
    assert goal[:3, 2] == pytest.approx(A_prime[:3, 2], abs=1e-12)
    assert abs(goal[:3, 0] @ UP) < 1e-12
    assert np.linalg.det(goal[:3, :3]) == pytest.approx(1.0)


def test_goal_with_tilted_worktable_normal():
    robot = six_joint_robot()
    up = np.array([0.3, -0.2, 1.0])
    observation = np.array([-0.02, 0.03, 0.28, -0.15, 0.05, 0.4])
    tracker = Tracker(robot, CAMERA, STANDOFF, up=up)
    goal = tracker.goal(np.zeros(6), observation)
    A = pose(rot("x", math.pi), [0.5, 0.0, 1.0])
    T = A @ pose(R_B[:3, :3], CAMERA + observation[:3]) @ pose(
        rot("z", 0.4) @ rot("y", 0.05) @ rot("x", -0.15), [0, 0, 0])
    A_prime = T @ np.linalg.inv(pose(R_B[:3, :3], [0, 0, STANDOFF]))
    assert goal == pytest.approx(level_pose(A_prime, up / np.linalg.norm(up)), abs=1e-12)


def test_observation_for_inverts_the_chain():
    robot = industrial_6r()
    q_capture = START["industrial_6r"]
    wanted = nominal_pose(robot, q_capture + np.array([0.1, -0.05, 0.05, 0.2, -0.1, 0.3]))
    observation = observation_for_pose(nominal_pose(robot, q_capture), wanted, CAMERA, STANDOFF)
    assert observation == pytest.approx(observation_for(robot, q_capture, wanted), abs=1e-12)
    goal = Tracker(robot, CAMERA, STANDOFF).goal(q_capture, observation)
    assert goal == pytest.approx(level_pose(wanted), abs=1e-12)


# ----------------------------------------------------------------------------- the NLP


@pytest.mark.parametrize("name", ["industrial_6r", "panda_7dof"])
def test_answers_meet_the_constraints(trackers, name):
    problem = trackers[name]
    robot = problem.robot
    rng = np.random.default_rng(3)
    tracker = Tracker(robot, CAMERA, STANDOFF, problem=problem)
    for _ in range(20):
        q_true = START[name] + rng.uniform(-0.15, 0.15, robot.dof)
        goal_unlevelled = nominal_pose(robot, q_true)
        q_capture = START[name] + rng.uniform(-0.05, 0.05, robot.dof)
        tracker.reset(START[name])
        step = tracker.step(q_capture, observation_for(robot, q_capture, goal_unlevelled))
        assert step.status == "ok", step
        assert step.constraint_error < 1e-9
        check_answer(robot, step.q, level_pose(goal_unlevelled))


def test_redundancy_goes_to_the_smallest_move_like_ipopt(trackers):
    problem = trackers["panda_7dof"]
    robot = problem.robot
    weights = np.array([1.0, 2.0, 1.0, 1.0, 0.5, 1.0, 3.0])
    fast = Tracker(robot, CAMERA, STANDOFF, weights=weights, problem=problem)
    reference = Tracker(robot, CAMERA, STANDOFF, weights=weights, method="ipopt",
                        problem=problem)
    rng = np.random.default_rng(5)
    for _ in range(5):
        q_capture = START["panda_7dof"]
        goal = nominal_pose(robot, q_capture + rng.uniform(-0.2, 0.2, 7))
        observation = observation_for(robot, q_capture, goal)
        fast.reset(q_capture)
        reference.reset(q_capture)
        a, b = fast.step(q_capture, observation), reference.step(q_capture, observation)
        assert a.ok and b.ok
        assert a.q == pytest.approx(b.q, abs=1e-6)


def test_looking_straight_down_every_turn_is_level_and_the_smallest_move_wins(trackers):
    # Joints 2 and 3 cancel and joint 5 is at 90 deg: the end z axis points straight down,
    # so every turn about it is level. The goal moves joint 1 by 0.05 rad and turns the
    # wrist by 0.3 rad; the turn is free, so the smallest move leaves joint 6 alone.
    problem = trackers["industrial_6r"]
    robot = problem.robot
    q0 = np.array([0.2, -0.3, 0.3, 0.0, math.pi / 2, 0.0])
    assert nominal_pose(robot, q0)[:3, 2] == pytest.approx([0, 0, -1], abs=1e-12)
    goal = nominal_pose(robot, q0 + np.array([0.05, 0, 0, 0, 0, 0.3]))
    tracker = Tracker(robot, CAMERA, STANDOFF, problem=problem)
    tracker.reset(q0)
    step = tracker.step(q0, observation_for(robot, q0, goal))
    assert step.ok, step
    assert step.constraint_error < 1e-9
    assert step.q == pytest.approx(q0 + np.array([0.05, 0, 0, 0, 0, 0]), abs=1e-9)


def test_joint_limits_hold_and_the_bound_is_used_optimally(trackers):
    robot = panda_7dof()
    q0 = START["panda_7dof"]
    goal = nominal_pose(robot, q0 + np.array([0.15, -0.1, 0.1, 0.1, -0.1, 0.1, 0.0]))
    observation = observation_for(robot, q0, goal)
    free = Tracker(robot, CAMERA, STANDOFF, problem=trackers["panda_7dof"])
    free.reset(q0)
    unconstrained = free.step(q0, observation)
    assert unconstrained.ok
    # Put an upper limit on the joint that moved up the most, half way: the answer must
    # respect it, meet the constraints, and agree with IPOPT on the same NLP.
    moved = unconstrained.q - q0
    j = int(np.argmax(moved))
    bound = q0[j] + 0.5 * moved[j]
    joints = list(robot.joints)
    joints[j] = dataclasses.replace(joints[j], limits=(joints[j].limits[0], bound))
    limited_robot = dataclasses.replace(robot, joints=tuple(joints))
    limited_problem = TrackingProblem(limited_robot)
    answers = []
    for method in ("gauss_newton", "ipopt"):
        tracker = Tracker(limited_robot, CAMERA, STANDOFF, method=method,
                          problem=limited_problem)
        tracker.reset(q0)
        step = tracker.step(q0, observation)
        assert step.ok, (method, step)
        assert step.q[j] <= bound
        check_answer(limited_robot, step.q, level_pose(goal))
        answers.append(step.q)
    assert answers[0][j] == pytest.approx(bound, abs=1e-9)  # the bound is active
    assert answers[0] == pytest.approx(answers[1], abs=1e-6)


# ----------------------------------------------------------------------------- behaviour


def lissajous_joints(name: str, cycles: int) -> np.ndarray:
    """A smooth joint path through reachable poses; on the 6R, joint 1 turns past pi."""
    t = np.linspace(0.0, 1.0, cycles)[:, None]
    n = len(START[name])
    amplitude = np.full(n, 0.25)
    frequency = np.arange(1, n + 1)
    path = START[name] + amplitude * np.sin(2 * np.pi * frequency * t + np.arange(n))
    if name == "industrial_6r":
        path[:, 0] = 2.7 + 0.5 * t[:, 0]  # joint 1 to 3.2 rad: beyond pi, within 185 deg
    return path


@pytest.mark.parametrize("name", ["industrial_6r", "panda_7dof"])
def test_long_smooth_trajectory_has_no_flips_or_turn_jumps(trackers, name):
    problem = trackers[name]
    robot = problem.robot
    cycles = 2000
    path = lissajous_joints(name, cycles)
    tracker = Tracker(robot, CAMERA, STANDOFF, problem=problem)
    tracker.reset(path[0])
    q_capture = path[0]
    answers = []
    for q_true in path:
        goal = nominal_pose(robot, q_true)
        step = tracker.step(q_capture, observation_for(robot, q_capture, goal))
        assert step.status == "ok", step
        answers.append(step.q)
        q_capture = step.q  # the robot went where it was told
    answers = np.array(answers)
    true_step = np.max(np.abs(np.diff(path, axis=0)))
    assert np.max(np.abs(np.diff(answers, axis=0))) < 5 * true_step + 0.02
    if name == "industrial_6r":
        # An isolated solution: the answer is the true joints with joint 6 levelled,
        # and joint 1 follows past pi without a 2 pi jump (3.2 - 2 pi is within its
        # limits too).
        assert answers[:, :5] == pytest.approx(path[:, :5], abs=1e-7)
        assert answers[-1, 0] > math.pi
    for q_true, q in zip(path[::97], answers[::97]):
        check_answer(robot, q, level_pose(nominal_pose(robot, q_true)))


def test_out_of_reach_target_is_unreachable_and_keeps_the_last_joints(trackers):
    problem = trackers["industrial_6r"]
    robot = problem.robot
    q0 = START["industrial_6r"]
    tracker = Tracker(robot, CAMERA, STANDOFF, problem=problem)
    tracker.reset(q0)
    good = tracker.step(q0, observation_for(robot, q0, nominal_pose(robot, q0 + 0.05)))
    assert good.ok
    far = observation_for(robot, q0, pose(np.eye(3), [5.0, 0.0, 1.0]))
    step = tracker.step(q0, far)
    assert step.status == "unreachable"
    assert np.array_equal(step.q, good.q)
    assert np.array_equal(tracker.previous, good.q)


def test_a_target_beyond_the_joint_limits_is_unreachable(trackers):
    robot = industrial_6r()
    q0 = START["industrial_6r"]
    q_goal = q0.copy()
    q_goal[4] = 1.3  # joint 5 upper limit 125 deg = 2.18 rad: fine
    goal = nominal_pose(robot, q_goal)
    # Shrink joint 5's range to exclude the answer (and its wrist-flipped twin).
    joints = list(robot.joints)
    joints[4] = dataclasses.replace(joints[4], limits=(0.5, 1.0))
    limited = dataclasses.replace(robot, joints=tuple(joints))
    tracker = Tracker(limited, CAMERA, STANDOFF)
    tracker.reset(q0)
    step = tracker.step(q0, observation_for(robot, q0, goal))
    assert step.status == "unreachable", step
    assert np.array_equal(step.q, q0)


def test_max_step_refuses_a_jump_and_allows_a_small_move(trackers):
    problem = trackers["industrial_6r"]
    robot = problem.robot
    start = START["industrial_6r"]
    free = Tracker(robot, CAMERA, STANDOFF, problem=problem)
    q0 = free.step(start, observation_for(robot, start, nominal_pose(robot, start))).q  # level
    tracker = Tracker(robot, CAMERA, STANDOFF, max_step=0.05, problem=problem)
    tracker.reset(q0)
    near = nominal_pose(robot, q0 + np.array([0.01, -0.01, 0.01, 0.0, 0.01, 0.0]))
    step = tracker.step(q0, observation_for(robot, q0, near))
    assert step.ok and np.max(np.abs(step.q - q0)) <= 0.05
    q_far = step.q + np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
    far = nominal_pose(robot, q_far)
    observation = observation_for(robot, step.q, far)
    # The jump needs 0.3 rad on joint 1: each cycle takes the largest allowed step
    # towards it (``limited``) until the goal is met, six cycles later.
    q = step.q
    statuses = []
    for _ in range(8):
        jump = tracker.step(step.q, observation)  # the same capture: the same goal
        statuses.append(jump.status)
        assert np.max(np.abs(jump.q - q)) <= 0.05 + 1e-12
        q = jump.q
    assert statuses == ["limited"] * 5 + ["ok"] * 3
    check_answer(robot, q, level_pose(far))
    assert q == pytest.approx(q_far, abs=1e-7)


def test_non_finite_observation_fails_safely(trackers):
    problem = trackers["industrial_6r"]
    q0 = START["industrial_6r"]
    tracker = Tracker(problem.robot, CAMERA, STANDOFF, problem=problem)
    tracker.reset(q0)
    step = tracker.step(q0, [0.0, 0.0, math.nan, 0.0, 0.0, 0.0])
    assert step.status == "failed" and np.array_equal(step.q, q0)


def test_track_step_is_frozen_and_readable(trackers):
    problem = trackers["industrial_6r"]
    q0 = START["industrial_6r"]
    tracker = Tracker(problem.robot, CAMERA, STANDOFF, problem=problem)
    step = tracker.step(q0, observation_for(problem.robot, q0, nominal_pose(problem.robot, q0)))
    with pytest.raises(dataclasses.FrozenInstanceError):
        step.status = "failed"  # type: ignore[misc]
    with pytest.raises(ValueError):
        step.q[0] = 1.0  # the answer cannot be changed behind the tracker's back
    assert "status='ok'" in repr(step) and "solve_ms" in repr(step)


def test_bad_arguments_are_refused():
    with pytest.raises(InputError, match="at least 6 joints"):
        Tracker(prismatic_rrp(), CAMERA, STANDOFF)
    robot = industrial_6r()
    with pytest.raises(InputError, match="camera_xyz"):
        Tracker(robot, [0.0, 0.1], STANDOFF)
    with pytest.raises(InputError, match="standoff"):
        Tracker(robot, CAMERA, -0.1)
    with pytest.raises(InputError, match="up"):
        Tracker(robot, CAMERA, STANDOFF, up=[0, 0, 0])
    with pytest.raises(InputError, match="max_step"):
        Tracker(robot, CAMERA, STANDOFF, max_step=[0.1, 0.1])


# ----------------------------------------------------------------------------- command line


def write_job(folder, robot: Robot, path: np.ndarray, *, units=Units("mm", "deg"),
              extra: dict | None = None) -> tuple:
    """A tracking job in ``units`` whose observations ask for the end poses of ``path``,
    captured at the previous row's joints."""
    save_robot(robot, folder / "robot.yaml")
    L, A = units.length_scale, units.angle_scale
    rows = []
    q_capture = path[0]
    for k, q_true in enumerate(path):
        observation = observation_for(robot, q_capture, nominal_pose(robot, q_true))
        rows.append([0.01 * k, *(q_capture / A), *(observation[:3] / L), *(observation[3:] / A)])
        q_capture = q_true
    columns = ["time", *(f"q{i}" for i in range(1, robot.dof + 1)),
               "x", "y", "z", "roll", "pitch", "yaw"]
    with open(folder / "observations.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(columns)
        writer.writerows([[repr(float(v)) for v in row] for row in rows])
    job = {"kind": "tracking", "robot": "robot.yaml", "units": units.as_dict(),
           "camera": {"xyz": [float(v) for v in CAMERA / L]}, "standoff": STANDOFF / L,
           "up": [0, 0, 1], "data": "observations.csv", **(extra or {})}
    (folder / "job.yaml").write_text(yaml.safe_dump(job))
    return folder / "job.yaml", rows


def read_csv(path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as handle:
        reader = csv.reader(handle)
        header = next(reader)
        return header, list(reader)


def test_cli_writes_the_contract_table(tmp_path, capsys):
    robot = industrial_6r()
    path = lissajous_joints("industrial_6r", 40)[:40]
    job, _ = write_job(tmp_path, robot, path)
    out = tmp_path / "joints.csv"
    assert main(["track", str(job), "--out", str(out)]) == 0
    header, rows = read_csv(out)
    assert header == ["time", "q1", "q2", "q3", "q4", "q5", "q6", "status", "solve_ms"]
    assert len(rows) == 40
    assert {r[7] for r in rows} == {"ok"}
    for k, row in enumerate(rows):
        assert float(row[0]) == pytest.approx(0.01 * k)
        q = np.array([float(v) for v in row[1:7]]) * math.pi / 180  # written in degrees
        check_answer(robot, q, level_pose(nominal_pose(robot, path[k])), tolerance=1e-8)
        assert float(row[8]) > 0
    assert "40 rows: 40 ok" in capsys.readouterr().out


def test_cli_calibrated_geometry_is_used(tmp_path):
    robot = industrial_6r()
    nominal = robot.parameter_vector()
    calibrated = robot.with_parameters(
        nominal + np.random.default_rng(1).normal(0, 2e-3, len(nominal)))
    path = lissajous_joints("industrial_6r", 10)
    job, _ = write_job(tmp_path, robot, path)
    (tmp_path / "result").mkdir()
    save_robot(calibrated, tmp_path / "result" / "robot_calibrated.yaml")
    out = tmp_path / "joints.csv"
    assert main(["track", str(job), "--out", str(out), "--calibrated",
                 str(tmp_path / "result")]) == 0
    _, rows = read_csv(out)
    # The same observations through the calibrated chain, in SI.
    tracker = Tracker(calibrated, CAMERA, STANDOFF)
    header, table = read_csv(tmp_path / "observations.csv")
    scales = np.array([1.0] + [math.pi / 180] * 6 + [1e-3] * 3 + [math.pi / 180] * 3)
    for row, answer in zip(table, rows):
        values = np.array([float(v) for v in row]) * scales
        step = tracker.step(values[1:7], values[7:13])
        assert answer[7] == step.status == "ok"
        assert np.array([float(v) for v in answer[1:7]]) * math.pi / 180 == pytest.approx(
            step.q, abs=1e-12)


@pytest.mark.parametrize("change, message", [
    ({"kind": "sphere_laser"}, "kind"),
    ({"standoff": -5}, "standoff"),
    ({"camera": {"xyz": [1, 2]}}, "camera.xyz"),
    ({"up": [0, 0, 0]}, "up"),
    ({"stand_off": 3}, "unknown key"),
    ({"data": "missing.csv"}, "not found"),
])
def test_cli_refuses_bad_jobs_and_writes_nothing(tmp_path, capsys, change, message):
    job, _ = write_job(tmp_path, industrial_6r(), lissajous_joints("industrial_6r", 3),
                       extra=change)
    out = tmp_path / "joints.csv"
    assert main(["track", str(job), "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert message in error
    assert "job.yaml" in error or "missing.csv" in error
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".joints")] == []


def test_cli_refuses_a_bad_observation_cell(tmp_path, capsys):
    job, _ = write_job(tmp_path, industrial_6r(), lissajous_joints("industrial_6r", 3))
    text = (tmp_path / "observations.csv").read_text().splitlines()
    cells = text[2].split(",")
    cells[-1] = "abc"
    text[2] = ",".join(cells)
    (tmp_path / "observations.csv").write_text("\n".join(text) + "\n")
    out = tmp_path / "joints.csv"
    assert main(["track", str(job), "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert "observations.csv" in error and "line 3" in error and "yaw" in error
    assert not out.exists()


def test_cli_row_out_of_reach_keeps_the_last_safe_joints(tmp_path):
    path = lissajous_joints("industrial_6r", 6)
    job, _ = write_job(tmp_path, industrial_6r(), path)
    header, table = read_csv(tmp_path / "observations.csv")
    table[3][header.index("z")] = "5000.0"  # 5 m in front of the camera
    with open(tmp_path / "observations.csv", "w", newline="") as handle:
        csv.writer(handle).writerows([header, *table])
    out = tmp_path / "joints.csv"
    assert main(["track", str(job), "--out", str(out)]) == 0
    _, rows = read_csv(out)
    assert [r[7] for r in rows] == ["ok", "ok", "ok", "unreachable", "ok", "ok"]
    assert rows[3][1:7] == rows[2][1:7]


def test_cli_max_step_in_job_units(tmp_path):
    robot = industrial_6r()
    start = START["industrial_6r"]
    level = Tracker(robot, CAMERA, STANDOFF).step(
        start, observation_for(robot, start, nominal_pose(robot, start))).q
    path = level + 0.002 * np.arange(4)[:, None]
    path[2:] -= 0.2  # a jump of 0.2 rad = 11.5 deg on every joint at row 2
    job, _ = write_job(tmp_path, robot, path)
    out = tmp_path / "joints.csv"
    assert main(["track", str(job), "--out", str(out), "--max-step", "5"]) == 0
    _, rows = read_csv(out)
    assert [r[7] for r in rows] == ["ok", "ok", "limited", "limited"]
    steps = np.abs(np.diff(np.array([[float(v) for v in r[1:7]] for r in rows]), axis=0))
    assert steps.max() <= 5 + 1e-9  # degrees
    assert main(["track", str(job), "--out", str(out), "--max-step", "30"]) == 0
    _, rows = read_csv(out)
    assert [r[7] for r in rows] == ["ok"] * 4
