"""Effects of arms that are not stiff: transmission coupling, hysteresis, and the inputs
they read from the row order. Each checked against its closed form written out here."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from robocal_casadi.effects import EFFECTS, Hysteresis, TransmissionCoupling
from robocal_casadi.effects.hysteresis import TRANSITION
from robocal_casadi.effects.motion import (
    direction_column,
    directions_of_motion,
    travel_column,
    travel_since_reversal,
    with_directions,
)
from robocal_casadi.errors import InputError
from robocal_casadi.examples import ROBOTS
from robocal_casadi.simulate import directions_in_order, simulate, travels_in_order

ROBOT = ROBOTS["industrial_6r"]()


def driven(robot, drive: str):
    return replace(robot, joints=tuple(replace(j, drive=drive) for j in robot.joints))


def test_transmission_coupling_is_a_share_of_the_driving_joints_angle():
    effect = TransmissionCoupling((5, 6, 5), drivers=(6, 5, 4))
    assert effect.parameter_names() == ("r5_q6", "r6_q5", "r5_q4")
    Q = np.array([[0.3, -0.5, 0.8, 1.1, -0.7, 2.5], [0.0, 0.1, 0.2, -0.4, 0.9, -1.5]])
    theta = np.array([2e-3, -1e-3, 5e-4])
    dq = effect.contribution(ROBOT, theta, Q, {}).dq
    expected = np.zeros_like(Q)
    expected[:, 4] = 2e-3 * Q[:, 5] + 5e-4 * Q[:, 3]
    expected[:, 5] = -1e-3 * Q[:, 4]
    np.testing.assert_allclose(dq, expected, atol=1e-18)
    with pytest.raises(InputError, match="joint_scale"):
        TransmissionCoupling((4,), drivers=(4,))
    units = TransmissionCoupling.candidates(ROBOT, {})
    assert len(units) == 30 and all(len(u.parameter_names()) == 1 for u in units)


def test_travel_since_reversal_follows_the_row_order():
    Q = np.array([[0.0, 1.0], [0.2, 1.0], [0.5, 0.7], [0.4, 0.7], [0.1, 0.9], [0.1, 1.0]])
    # joint 1: up 0.2, up 0.3 (0.5 in all), reverse 0.1, down 0.3 more, still
    # joint 2: still, first move down 0.3, still, reverse up 0.2, up 0.1
    expected = [[0, 0], [0.2, 0], [0.5, 0.3], [0.1, 0.3], [0.4, 0.2], [0.4, 0.3]]
    np.testing.assert_allclose(travel_since_reversal(Q), expected, atol=1e-15)
    # the simulator's own coding agrees
    np.testing.assert_allclose(travels_in_order(Q), expected, atol=1e-15)
    np.testing.assert_array_equal(directions_in_order(Q), directions_of_motion(Q))
    extras = with_directions(Q, {})
    np.testing.assert_allclose(extras[travel_column(1)], np.array(expected)[:, 0])


def test_hysteresis_comes_over_smoothly_and_backlash_is_its_sharp_limit():
    cable = driven(ROBOT, "cable")
    effect = Hysteresis((2,))
    w = TRANSITION["cable"]
    h = 1e-3
    travel = np.array([0.0, 0.5 * w, w, 3 * w, 30 * w])
    extras = {direction_column(2): np.ones(5), travel_column(2): travel}
    Q = np.zeros((5, 6))
    dq = effect.contribution(cable, [h], Q, extras).dq[:, 1]
    np.testing.assert_allclose(dq, -0.5 * h * (1 - 2 * np.exp(-travel / w)), rtol=1e-12)
    assert dq[0] == pytest.approx(+h / 2)  # just reversed: still lags the other way
    assert dq[-1] == pytest.approx(-h / 2, rel=1e-9)  # came over: backlash's value
    backlash = EFFECTS["backlash"]((2,)).contribution(cable, [h], Q, extras).dq[:, 1]
    np.testing.assert_allclose(dq[-1], backlash[-1], rtol=1e-9)
    # the transition of a stiffer drive is sharper
    geared = effect.contribution(ROBOT, [h], Q, extras).dq[:, 1]
    assert abs(geared[1] - backlash[1]) < abs(dq[1] - backlash[1])


def test_hysteresis_is_looked_for_where_backlash_is_not():
    mixed = replace(ROBOT, joints=tuple(replace(j, drive=d) for j, d in zip(
        ROBOT.joints, ["cable", "gear", "harmonic", "cycloid", "belt", "direct"])))
    hysteresis = sorted(j for u in Hysteresis.candidates(mixed, {}) for j in u.joints)
    backlash = sorted(j for u in EFFECTS["backlash"].candidates(mixed, {}) for j in u.joints)
    assert hysteresis == [1, 3, 5, 6] and backlash == [2, 4]


def test_hysteresis_is_simulated_for_tracker_data_only(tmp_path):
    with pytest.raises(InputError, match="tracker_points"):
        simulate(driven(ROBOT, "cable"), "artifact_touches", out_dir=tmp_path / "a", rows=4,
                 effects={"hysteresis": {2: 1e-3}}, progress=False)


def test_simulated_hysteresis_follows_the_written_order(tmp_path):
    """The truth of a simulated table: true joints differ from the readings by the loop's
    offset at each row's direction and travel, recomputed here from the written rows."""
    from robocal_casadi.simulate import TrueRobot

    robot = driven(ROBOT, "cable")
    h, w = 2e-3, TRANSITION["cable"]
    sim = simulate(robot, "tracker_points", out_dir=tmp_path / "t", rows=30, noise=0.0,
                   effects={"hysteresis": {1: h}}, seed=3, progress=False)
    q = sim.joints[:, 0]
    world = TrueRobot(sim.truth.robot, sim.truth.effects, 20.0, np.zeros(3))
    dq = world.true_joints(sim.joints, np.zeros(len(q)))[:, 0] - q
    expected, last, travel = [0.0], 0.0, 0.0
    for i in range(1, len(q)):
        direction = math.copysign(1.0, q[i] - q[i - 1])  # random rows always move
        travel = abs(q[i] - q[i - 1]) + (travel if direction == last else 0.0)
        expected.append(-0.5 * h * direction * (1 - 2 * math.exp(-travel / w)))
        last = direction
    np.testing.assert_allclose(dq, expected, rtol=1e-12, atol=1e-18)
    assert np.abs(dq).max() == pytest.approx(h / 2, rel=1e-6)
