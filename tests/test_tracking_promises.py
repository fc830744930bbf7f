"""What a controller is promised at a target jump, with a step bound, and from a cold start.

Independent checks: every answer is judged by pinocchio's forward kinematics (not the
package's own CasADi chain) against the goal pose; the smallest move is checked by
brute force over every equivalent branch of the answer (whole turns of each revolute
joint within its limits, half turns of the last joint), each branch judged by pinocchio.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from robocal_casadi.model.examples import industrial_6r, panda_7dof
from robocal_casadi.model.ik import random_joints
from robocal_casadi.model.kinematics import nominal_pose
from robocal_casadi.model.pinocchio_model import pinocchio_tool_pose
from robocal_casadi.tracking import Tracker, TrackingProblem, observation_for
from robocal_casadi.tracking.tracker import ANGLE_TOLERANCE, POSITION_TOLERANCE

CAMERA = np.array([0.04, -0.03, 0.06])  # [m]
STANDOFF = 0.25  # [m]
UP = np.array([0.0, 0.0, 1.0])
START = np.array([0.2, -0.4, 0.5, 0.3, 0.9, 0.2])


def meets(robot, q, goal, tolerance=1e-8) -> bool:
    """Pinocchio's end pose at ``q`` on the goal: position, z axis, x axis level, limits."""
    T = pinocchio_tool_pose(robot, q)
    return bool(np.linalg.norm(T[:3, 3] - goal[:3, 3]) < tolerance
                and np.linalg.norm(np.cross(T[:3, 2], goal[:3, 2])) < tolerance
                and T[:3, 2] @ goal[:3, 2] > 0
                and abs(UP @ T[:3, 0]) < tolerance
                and np.all(q >= robot.lower_limits - 1e-12)
                and np.all(q <= robot.upper_limits + 1e-12))


def branches(robot, q):
    """Every joint vector equivalent to ``q`` by whole turns within the limits, and by
    half turns of the last joint (equivalence judged by ``meets`` afterwards)."""
    options = []
    for j, joint in enumerate(robot.joints):
        step = math.pi if j == robot.dof - 1 else 2 * math.pi
        values = [q[j] + k * step for k in range(-4, 5)] if joint.revolute else [q[j]]
        options.append([v for v in values
                        if robot.lower_limits[j] <= v <= robot.upper_limits[j]])
    return [np.array(c) for c in itertools.product(*options)]


@pytest.fixture(scope="module")
def problem():
    return TrackingProblem(industrial_6r())


def level_start(tracker, robot):
    tracker.reset(START)
    pose = nominal_pose(robot, START)
    return tracker.step(START, observation_for(pose, pose, CAMERA, STANDOFF)).q


def test_at_a_target_jump_the_smallest_equivalent_move_wins(problem):
    robot = problem.robot
    tracker = Tracker(robot, CAMERA, STANDOFF, problem=problem)
    q0 = level_start(tracker, robot)
    rng = np.random.default_rng(0)
    alternatives = 0
    for _ in range(40):
        tracker.reset(q0)
        q_target = q0 + rng.uniform(-1.0, 1.0, 6)
        observation = observation_for(nominal_pose(robot, q0), nominal_pose(robot, q_target),
                                      CAMERA, STANDOFF)
        goal = tracker.goal(q0, observation)
        step = tracker.step(q0, observation)
        assert step.ok, step
        assert meets(robot, step.q, goal)
        equivalent = [b for b in branches(robot, step.q) if meets(robot, b, goal)]
        alternatives += len(equivalent) > 1
        best = min(float(np.sum((b - q0) ** 2)) for b in equivalent)
        assert float(np.sum((step.q - q0) ** 2)) == pytest.approx(best, abs=1e-12)
        assert abs(step.q[5] - q0[5]) <= math.pi / 2 + 1e-9  # no wrist spin
    assert alternatives == 40  # the half turn of joint 6 always meets the goal too


def test_a_step_bound_approaches_a_reachable_goal_and_then_meets_it(problem):
    robot = problem.robot
    free = Tracker(robot, CAMERA, STANDOFF, problem=problem)
    q0 = level_start(free, robot)
    max_step = 0.02
    tracker = Tracker(robot, CAMERA, STANDOFF, max_step=max_step, problem=problem)
    tracker.reset(q0)
    # 60 rows of one target 0.25 rad away on two joints: reachable, far beyond one step.
    q_target = q0 + np.array([0.25, -0.2, 0.0, 0.0, 0.0, 0.0])
    observation = observation_for(nominal_pose(robot, q0), nominal_pose(robot, q_target),
                                  CAMERA, STANDOFF)
    goal = tracker.goal(q0, observation)
    q, statuses = q0, []
    for _ in range(60):
        step = tracker.step(q0, observation)
        assert np.max(np.abs(step.q - q)) <= max_step + 1e-12
        assert np.all(step.q >= robot.lower_limits) and np.all(step.q <= robot.upper_limits)
        statuses.append(step.status)
        q = step.q
    k = statuses.index("ok")
    assert statuses == ["limited"] * k + ["ok"] * (60 - k)
    assert 10 <= k <= 16  # 0.25 rad at 0.02 rad per row
    assert meets(robot, q, goal)


def test_limited_steps_move_straight_towards_the_answer(problem):
    robot = problem.robot
    free = Tracker(robot, CAMERA, STANDOFF, problem=problem)
    q0 = level_start(free, robot)
    q_target = q0 + np.array([0.3, -0.1, 0.05, 0.0, 0.0, 0.0])
    observation = observation_for(nominal_pose(robot, q0), nominal_pose(robot, q_target),
                                  CAMERA, STANDOFF)
    free.reset(q0)
    answer = free.step(q0, observation).q
    bounded = Tracker(robot, CAMERA, STANDOFF, max_step=0.05, problem=problem)
    bounded.reset(q0)
    step = bounded.step(q0, observation)
    assert step.status == "limited"
    move = step.q - q0
    assert np.max(np.abs(move)) == pytest.approx(0.05, abs=1e-12)
    assert move / 0.05 == pytest.approx((answer - q0) / np.max(np.abs(answer - q0)), abs=1e-9)
    assert step.position_error > 1e-3  # honest about not being there yet


@pytest.mark.parametrize("make", [industrial_6r, panda_7dof])
def test_a_cold_start_far_from_the_answer_is_seeded_from_inverse_kinematics(make):
    robot = make()
    tracker = Tracker(robot, CAMERA, STANDOFF)
    rng = np.random.default_rng(1)
    targets = random_joints(robot, 8, rng, margin=0.1)
    starts = random_joints(robot, 8, rng, margin=0.1)
    for q_target, q_start in zip(targets, starts):
        observation = observation_for(nominal_pose(robot, q_start),
                                      nominal_pose(robot, q_target), CAMERA, STANDOFF)
        tracker.reset()
        step = tracker.step(q_start, observation)
        assert step.ok, step
        # within what "ok" promises: a solve from far away may stop short of rounding
        # level (one BLAS kernel converges to 1e-12, another stops at 8e-8)
        assert meets(robot, step.q, tracker.goal(q_start, observation),
                     tolerance=max(POSITION_TOLERANCE, ANGLE_TOLERANCE))


def test_without_inverse_kinematics_the_cold_start_is_mostly_unreachable():
    """The cases above with the warm start alone: the seeding is what solves them."""
    robot = industrial_6r()
    tracker = Tracker(robot, CAMERA, STANDOFF, seed_from_ik=False)
    rng = np.random.default_rng(1)
    targets = random_joints(robot, 8, rng, margin=0.1)
    starts = random_joints(robot, 8, rng, margin=0.1)
    statuses = []
    for q_target, q_start in zip(targets, starts):
        observation = observation_for(nominal_pose(robot, q_start),
                                      nominal_pose(robot, q_target), CAMERA, STANDOFF)
        tracker.reset()
        statuses.append(tracker.step(q_start, observation).status)
    assert statuses.count("unreachable") >= 5, statuses
