"""Tracking through a degenerate orientation (the tool axis along the worktable normal)
and under the job's joint speed limits.

The path keeps joints 2 and 3 cancelling on the example 6R, so the end z axis passes
within ``miss`` [rad] of straight down while joint 5 sweeps through 90 deg: the level
direction of the x axis turns by about a half turn within a few rows there. Answers are
judged by numpy forward kinematics, independently of the CasADi chain.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_tracking import CAMERA, STANDOFF, observation_for, read_csv, write_job

from robocal_casadi.cli import main
from robocal_casadi.model.examples import industrial_6r
from robocal_casadi.model.kinematics import nominal_pose
from robocal_casadi.tracking import Tracker
from robocal_casadi.tracking.problem import DEGENERATE_TILT

UP = np.array([0.0, 0.0, 1.0])


def sweep(miss: float, rows: int = 41) -> np.ndarray:
    """Joints [rad] whose end z axis passes ``miss`` from vertical at the middle row."""
    s = np.linspace(-1.0, 1.0, rows)
    path = np.tile([0.2, -0.3, 0.3, miss, math.pi / 2, 0.0], (rows, 1))
    path[:, 4] += 0.05 * s
    path[:, 0] += 0.02 * s
    return path


def tilt(robot, q) -> float:
    """Angle [rad] between the end z axis at ``q`` and the vertical."""
    z = nominal_pose(robot, q)[:3, 2]
    return float(np.arcsin(min(1.0, np.linalg.norm(np.cross(UP, z)))))


@pytest.mark.parametrize("miss", [0.0, 1e-4])
def test_near_vertical_the_turn_is_free_and_the_last_joint_stays(miss):
    robot = industrial_6r()
    path = sweep(miss)
    tracker = Tracker(robot, CAMERA, STANDOFF)
    tracker.reset(path[0])
    q_capture, answers = path[0], []
    for q_true in path:
        step = tracker.step(q_capture, observation_for(robot, q_capture,
                                                       nominal_pose(robot, q_true)))
        assert step.ok, step
        T, goal = nominal_pose(robot, step.q), nominal_pose(robot, q_true)
        assert np.linalg.norm(T[:3, 3] - goal[:3, 3]) < 1e-9
        assert np.linalg.norm(np.cross(T[:3, 2], goal[:3, 2])) < 1e-9
        # level exactly, or within the goal's own tilt inside the free cone
        allowed = tilt(robot, q_true) if tilt(robot, q_true) <= DEGENERATE_TILT else 0.0
        assert abs(UP @ T[:3, 0]) <= math.sin(allowed) + 1e-9
        answers.append(step.q)
        q_capture = step.q
    answers = np.array(answers)
    free = [k for k, q in enumerate(path) if tilt(robot, q) <= DEGENERATE_TILT]
    assert free  # the sweep does pass through the free cone
    for k in free:  # joint 6 turns the end about z alone: the smallest move leaves it
        assert abs(answers[k, 5] - answers[k - 1, 5]) < 1e-9
    # without the free cone the level direction swings by up to 90 deg in one row here;
    # with it the largest turn of joint 6 is that of the rows just outside the cone
    assert np.max(np.abs(np.diff(answers[:, 5]))) < math.radians(10.0)


def test_job_speed_limits_bound_every_row_and_mark_the_rest_limited(tmp_path):
    """A sweep that misses vertical by 0.01 rad needs joint 6 to turn about 14 deg per
    10 ms row; at 360 deg/s a row may move 3.6 deg: those rows are limited, and no row
    (ok or limited) moves a joint more than its speed allows."""
    robot = industrial_6r()
    path = sweep(0.01)
    first = Tracker(robot, CAMERA, STANDOFF).step(
        path[0], observation_for(robot, path[0], nominal_pose(robot, path[0])))
    path[:, 5] = first.q[5]  # start level: the first row asks for no turn
    job, _ = write_job(tmp_path, robot, path, extra={"max_velocity": 360})
    out = tmp_path / "joints.csv"
    assert main(["track", str(job), "--out", str(out)]) == 0
    _, rows = read_csv(out)
    times = np.array([float(r[0]) for r in rows])
    joints = np.array([[float(v) for v in r[1:7]] for r in rows])  # deg
    status = [r[7] for r in rows]
    allowed = 360.0 * np.diff(times)
    moves = np.abs(np.diff(joints, axis=0)).max(axis=1)
    assert np.all(moves <= allowed + 1e-9)
    assert "limited" in status and status[0] == "ok"
    for k in range(1, len(rows)):  # an ok row meets its goal within the speed allowed
        if status[k] == "ok":
            T = nominal_pose(robot, np.radians(joints[k]))
            assert np.linalg.norm(T[:3, 3] - nominal_pose(robot, path[k])[:3, 3]) < 1e-8
    # without the limit the same job jumps further than the limit allows, marked ok
    free_job, _ = write_job(tmp_path, robot, path)
    assert main(["track", str(free_job), "--out", str(out)]) == 0
    _, rows = read_csv(out)
    joints = np.array([[float(v) for v in r[1:7]] for r in rows])
    assert {r[7] for r in rows} == {"ok"}
    assert np.abs(np.diff(joints, axis=0)).max() > 3.6


@pytest.mark.parametrize("value, message", [(-1, "positive"), ([1, 2], "list of 6"),
                                            ("fast", "expected a number")])
def test_bad_speed_limits_are_refused(tmp_path, capsys, value, message):
    job, _ = write_job(tmp_path, industrial_6r(), sweep(0.0, 3), extra={"max_velocity": value})
    out = tmp_path / "joints.csv"
    assert main(["track", str(job), "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "max_velocity" in error and message in error
    assert not out.exists()


def test_a_job_through_the_degenerate_case_runs_ok_within_its_speed_limits(tmp_path):
    """The same sweep as a job, 1e-4 rad from vertical at its middle row, with joints
    limited to 720 deg/s: past the free row the level direction asks joint 6 for a few
    degrees, so every row is met (ok) and none moves a joint more than 7.2 deg (without
    the free turn it would ask for a half turn there)."""
    robot = industrial_6r()
    path = sweep(1e-4)
    first = Tracker(robot, CAMERA, STANDOFF).step(
        path[0], observation_for(robot, path[0], nominal_pose(robot, path[0])))
    path[:, 5] = first.q[5]  # start level
    job, _ = write_job(tmp_path, robot, path, extra={"max_velocity": 720})
    out = tmp_path / "joints.csv"
    assert main(["track", str(job), "--out", str(out)]) == 0
    _, rows = read_csv(out)
    assert {r[7] for r in rows} == {"ok"}
    joints = np.array([[float(v) for v in r[1:7]] for r in rows])  # deg
    assert np.abs(np.diff(joints, axis=0)).max() <= 7.2 + 1e-9
