"""Joint drives in the robot file, and the plausible effect sizes that depend on them."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from robocal_casadi.calibration import calibrate
from robocal_casadi.calibration.drive_hints import drive_lines
from robocal_casadi.commands.calibrate import summary
from robocal_casadi.effects import EFFECTS
from robocal_casadi.effects.drives import drives_allowing
from robocal_casadi.errors import InputError
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import ROBOTS
from robocal_casadi.model.robot import DRIVES, load_robot, save_robot

ROBOT_TEXT = """\
convention: dh
units: {length: mm, angle: deg}
joints:
  - {theta: 0, d: 300, a: 0, alpha: -90, drive: cable}
  - {theta: 0, d: 0, a: 400, alpha: 0, drive: harmonic}
  - {theta: 0, d: 0, a: 300, alpha: 0}
"""


def with_drives(robot, drives):
    """``robot`` with ``drives`` (one per joint)."""
    return replace(robot, joints=tuple(replace(j, drive=d) for j, d in zip(robot.joints, drives)))


def test_drive_is_read_defaults_to_gear_and_survives_a_round_trip(tmp_path):
    path = tmp_path / "r.yaml"
    path.write_text(ROBOT_TEXT)
    robot = load_robot(path)
    assert [robot.drive(j) for j in (1, 2, 3)] == ["cable", "harmonic", "gear"]
    save_robot(robot, tmp_path / "back.yaml")
    text = (tmp_path / "back.yaml").read_text()
    assert text.count("drive:") == 2  # the default is not written
    assert load_robot(tmp_path / "back.yaml") == robot


def test_an_unknown_drive_is_refused_with_the_joint_and_the_choices(tmp_path):
    path = tmp_path / "r.yaml"
    path.write_text(ROBOT_TEXT.replace("drive: harmonic", "drive: chain"))
    with pytest.raises(InputError) as caught:
        load_robot(path)
    message = str(caught.value)
    assert "joint 2" in message and ".drive" in message and "chain" in message
    assert all(d in message for d in DRIVES)


@pytest.mark.parametrize("name,parameter,value", [
    ("joint_compliance", "c2", 2e-3),   # a cable-driven joint's compliance
    ("joint_scale", "s2", 1.5e-2),      # a capstan radius 1.5 % off
    ("joint_coupling", "sin2_q3", math.radians(0.3)),
    ("joint_cyclic", "a1_2", math.radians(0.3)),
])
def test_sizes_a_gearbox_never_shows_are_plausible_on_a_cable_drive(name, parameter, value):
    """The same estimate: absurd on a geared joint, plausible on a cable-driven one."""
    geared = ROBOTS["industrial_6r"]()
    cabled = with_drives(geared, ["gear", "cable"] + ["gear"] * 4)
    cls = EFFECTS[name]
    effect = cls((2,), (3,)) if cls.per == "pair" else cls((2,))
    assert effect.implausibility({parameter: value}, geared), "a gearbox range lets it pass"
    assert effect.implausibility({parameter: value}, cabled) == ""
    # ranges only widen from gear to cable, and the words say which drive
    gear, cable = effect.plausible(parameter, "gear"), effect.plausible(parameter, "cable")
    assert cable.maximum > gear.maximum and "cable" in cable.basis


def test_every_effect_states_a_range_for_every_drive():
    robot = ROBOTS["industrial_6r"]()
    for cls in EFFECTS.values():
        units = cls.candidates(robot, {"temperature": [20.0, 21.0]})
        if not units:
            continue
        effect = units[0]
        for parameter in effect.parameter_names():
            for drive in DRIVES:
                limits = effect.plausible(parameter, drive)
                assert 0 <= limits.minimum <= limits.maximum and limits.basis, (cls.name, drive)


def test_backlash_is_looked_for_on_geared_joints_only():
    robot = with_drives(ROBOTS["industrial_6r"](), ["cable", "gear", "cycloid", "harmonic",
                                                    "belt", "direct"])
    units = EFFECTS["backlash"].candidates(robot, {})
    assert sorted(j for u in units for j in u.joints) == [2, 3]


def test_the_drives_that_allow_a_size_nearest_first():
    robot = ROBOTS["industrial_6r"]()
    scale = EFFECTS["joint_scale"]((2,))
    # 0.8 %: beyond a gear train's 0.2 %, within a belt's 1 % and a cable's 3 %
    assert drives_allowing(scale, {"s2": 0.008}, robot) == ((2, ("belt", "cable")),)
    assert drives_allowing(scale, {"s2": 0.001}, robot) == ()  # plausible as it is
    assert drives_allowing(scale, {"s2": 0.05}, robot) == ()  # no drive shows 5 %
    cabled = with_drives(robot, ["gear", "cable"] + ["gear"] * 4)
    assert drives_allowing(scale, {"s2": 0.02}, cabled) == ()


def test_a_size_refused_on_the_default_gear_points_to_the_drive(tmp_path):
    """A belt-driven joint 2 whose ratio is 0.8 % off, in a robot file without drive:
    refused on the default gear, with the line that allows it; declared, found."""
    robot = ROBOTS["industrial_6r"]()
    simulated = simulate(robot, "tracker_points", out_dir=tmp_path / "d", rows=200,
                         noise=1e-5, seed=5, geometric_errors={"a2": 3e-4},
                         effects={"joint_scale": {2: 0.008}}, progress=False)
    result = calibrate([simulated.load()])
    assert "joint_scale" not in [e.name for e in result.effects]
    hints = drive_lines(result)
    ours = [line for line in hints if line.startswith("joint 2:")]
    assert len(ours) == 1 and "joint_scale[2]" in ours[0] and "`drive: belt`" in ours[0], hints
    assert summary(result).count("joint 2: joint_scale[2]") == 1  # said once
    assert result.robot_calibrated.drive(2) == "gear"  # never switched silently
    belted = with_drives(robot, ["gear", "belt"] + ["gear"] * 4)
    declared = calibrate([load_dataset(simulated.dataset_path, robot=belted)])
    found = [e for e in declared.effects if e.name == "joint_scale"]
    assert len(found) == 1 and found[0].joints == (2,)
    assert found[0].parameters["s2"] == pytest.approx(0.008, rel=0.1)
    assert not [line for line in drive_lines(declared) if line.startswith("joint 2:")]
