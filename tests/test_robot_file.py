"""Robot files: every field read in its units, written back and read again unchanged;
bad files refused with the file and the key in the message."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal_casadi.errors import InputError
from robocal_casadi.model.robot import load_robot, save_robot

MM_DEG = """\
name: test-arm
convention: dh
units: {length: mm, angle: deg}
joints:
  - {type: revolute, theta: 12.5, d: 675.0, a: 260.125, alpha: -90, limits: [-185, 185], mass: 60.5, com: [1.5, 50.25, -3]}
  - {type: revolute, theta: -90, d: 0.001, a: 680.3, alpha: 0.0, beta: 0.0123, limits: [-140, 80]}
  - {type: prismatic, theta: 7.25, d: 33.3, a: -35.7, alpha: 90.5, limits: [-12.5, 300.75], mass: 2.25, com: [0, 0, 100.1]}
  - {type: revolute, theta: 0.1, d: -670.9, a: 0.2, alpha: -89.97, beta: -0.5}
base: {xyz: [100.1, -200.2, 3.3], rpy: [0.5, -1.25, 179.9]}
tool: {xyz: [0.7, 1.1, 150.05], rpy: [-30.3, 45.45, 0.001]}
gravity: [0.1, -0.2, -9.80665]
"""

M_RAD = """\
name: test-panda
convention: mdh
units: {length: m, angle: rad}
joints:
  - {type: revolute, theta: 0.0, d: 0.333, a: 0.0, alpha: 0.0, limits: [-2.8973, 2.8973], mass: 4.97, com: [0.003875, 0.002081, -0.04762]}
  - {type: revolute, theta: 0.001, d: 0.0, a: 0.0, alpha: -1.5707963267948966, beta: 0.0021, limits: [-1.7628, 1.7628]}
  - {type: prismatic, theta: 0.0, d: 0.316, a: 0.0825, alpha: 1.5707963267948966, limits: [0.0, 0.4]}
base: {xyz: [0.1, 0.2, 0.3], rpy: [0.01, -0.02, 3.1]}
tool: {xyz: [0.0, 0.0, 0.107], rpy: [0.0, 0.0, -0.7853981633974483]}
gravity: [0.0, 0.0, -9.81]
"""


def write(folder: Path, text: str, name: str = "robot.yaml") -> Path:
    path = folder / name
    path.write_text(text)
    return path


def numbers_of(content) -> list[float]:
    """Every number of a YAML mapping, in reading order (keys sorted for stability)."""
    if isinstance(content, dict):
        return [v for key in sorted(content) for v in numbers_of(content[key])]
    if isinstance(content, list):
        return [v for item in content for v in numbers_of(item)]
    if isinstance(content, (int, float)) and not isinstance(content, bool):
        return [float(content)]
    return []


@pytest.mark.parametrize("text", [MM_DEG, M_RAD], ids=["mm_deg", "m_rad"])
def test_round_trip_keeps_every_field(tmp_path, text):
    original = load_robot(write(tmp_path, text))
    saved = tmp_path / "saved.yaml"
    save_robot(original, saved)
    again = load_robot(saved)
    assert again == original  # every field, SI values bit for bit, units and flags
    written, source = yaml.safe_load(saved.read_text()), yaml.safe_load(text)
    assert written["units"] == source["units"]
    assert [j.get("type") for j in written["joints"]] == [j.get("type") for j in source["joints"]]
    assert [sorted(j) for j in written["joints"]] == [sorted(j) for j in source["joints"]]
    # File numbers come back in the file's units; a unit conversion may move the last bit.
    np.testing.assert_array_max_ulp(np.array(numbers_of(written)), np.array(numbers_of(source)),
                                    maxulp=1)


def test_values_are_read_in_si(tmp_path):
    robot = load_robot(write(tmp_path, MM_DEG))
    deg = math.pi / 180
    first, second, prismatic, last = robot.joints
    assert robot.convention == "dh" and robot.units.length == "mm" and robot.units.angle == "deg"
    assert first.d == pytest.approx(0.675, rel=1e-15)
    assert first.theta == pytest.approx(12.5 * deg, rel=1e-15)
    assert first.limits == pytest.approx((-185 * deg, 185 * deg), rel=1e-15)
    assert first.mass == 60.5 and first.com == pytest.approx((1.5e-3, 50.25e-3, -3e-3), rel=1e-15)
    assert second.beta == pytest.approx(0.0123 * deg, rel=1e-15) and second.has_beta
    assert prismatic.type == "prismatic" and not prismatic.revolute
    assert prismatic.limits == pytest.approx((-12.5e-3, 300.75e-3), rel=1e-15)  # a length
    assert last.limits is None and last.mass is None and last.com is None
    assert robot.base.xyz == pytest.approx((0.1001, -0.2002, 0.0033), rel=1e-15)
    assert robot.base.rpy == pytest.approx((0.5 * deg, -1.25 * deg, 179.9 * deg), rel=1e-15)
    assert robot.tool.xyz[2] == pytest.approx(0.15005, rel=1e-15)
    assert robot.gravity == (0.1, -0.2, -9.80665)  # m/s^2 whatever the file's length unit


def test_saving_in_other_units_reads_back_the_same_robot(tmp_path):
    original = load_robot(write(tmp_path, MM_DEG))
    from robocal_casadi.common.units import SI

    save_robot(original, tmp_path / "si.yaml", units=SI)
    again = load_robot(tmp_path / "si.yaml")
    assert again.units == SI
    a, b = original.parameter_vector(), again.parameter_vector()
    np.testing.assert_allclose(b, a, rtol=1e-15, atol=1e-18)


VALID_JOINT = "{type: revolute, theta: 0, d: 100, a: 20, alpha: 90, limits: [-90, 90]}"


def robot_text(convention="dh", units="{length: mm, angle: deg}", joint=VALID_JOINT) -> str:
    return f"convention: {convention}\nunits: {units}\njoints:\n  - {joint}\n  - {VALID_JOINT}\n"


BAD_FILES = {
    "unknown convention": (robot_text(convention="craig"), "convention", "craig"),
    "missing joint field": (robot_text(joint="{type: revolute, theta: 0, a: 20, alpha: 90}"),
                            "joints[0] (joint 1).d", "missing"),
    "wrong length unit": (robot_text(units="{length: inch, angle: deg}"), "units.length", "inch"),
    "wrong angle unit": (robot_text(units="{length: mm, angle: grad}"), "units.angle", "grad"),
    "non-numeric value": (robot_text(joint="{type: revolute, theta: 0, d: 1O0, a: 20, alpha: 90}"),
                          "joints[0] (joint 1).d", "1O0"),
    "NaN": (robot_text(joint="{type: revolute, theta: 0, d: 100, a: .nan, alpha: 90}"),
            "joints[0] (joint 1).a", "finite"),
    "limits reversed": (robot_text(joint="{type: revolute, theta: 0, d: 1, a: 2, alpha: 0, "
                                         "limits: [90, -90]}"), "joints[0] (joint 1).limits", "90"),
    "unknown joint type": (robot_text(joint="{type: helical, theta: 0, d: 1, a: 2, alpha: 0}"),
                           "joints[0] (joint 1).type", "helical"),
    "NaN in base": (robot_text() + "base: {xyz: [0, .nan, 0]}\n", "base.xyz[1]", "finite"),
}


@pytest.mark.parametrize("case", list(BAD_FILES))
def test_bad_robot_file_names_file_and_key(tmp_path, case):
    text, key, detail = BAD_FILES[case]
    path = write(tmp_path, text, "arm.yaml")
    with pytest.raises(InputError) as raised:
        load_robot(path)
    message = str(raised.value)
    assert str(path) in message and key in message and detail in message
    assert "\n" not in message


def test_missing_robot_file(tmp_path):
    path = tmp_path / "absent.yaml"
    with pytest.raises(InputError, match="absent.yaml: robot file not found"):
        load_robot(path)


@pytest.mark.parametrize("typed_m, written_mm", [(-0.5723, -572.3), (0.1157, 115.7),
                                                 (0.163941, 163.941), (1e-3, 1.0)])
def test_values_typed_in_metres_are_written_in_mm_as_typed(tmp_path, typed_m, written_mm):
    """A length typed in metres reads as the same decimal in mm (robot file written in mm,
    result.json's nominal), not as the last-bit neighbour ``-572.3000000000001``."""
    from robocal_casadi.common.units import Units
    from robocal_casadi.results import ParameterEstimate

    text = ("convention: dh\nunits: {length: m, angle: rad}\njoints:\n"
            f"  - {{type: revolute, theta: 0, d: {typed_m!r}, a: 0, alpha: 0}}\n")
    robot = load_robot(write(tmp_path, text))
    mm = Units("mm", "deg")
    save_robot(robot, tmp_path / "mm.yaml", units=mm)
    assert yaml.safe_load((tmp_path / "mm.yaml").read_text())["joints"][0]["d"] == written_mm
    row = ParameterEstimate("d1", "length", robot.joints[0].d, robot.joints[0].d, None, False)
    assert row.to_json(mm)["nominal"] == written_mm
    again = load_robot(tmp_path / "mm.yaml")  # within one unit in the last place
    np.testing.assert_array_max_ulp(again.joints[0].d, robot.joints[0].d, maxulp=1)
