"""URDF robots: the chain read from a URDF file against pinocchio's own URDF parser, the
DH files of the same robots, and calibration on simulated data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml
from urdf_robots import panda_urdf, ur10_urdf, write

from robocal_casadi.calibration import calibrate
from robocal_casadi.cli import main
from robocal_casadi.errors import InputError
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.kinematics import Kinematics
from robocal_casadi.model.robot import load_robot, robot_from_dict, robot_to_dict

PACKAGE_DATA = Path(__file__).resolve().parents[1] / "robocal_casadi" / "data"
UR10_DH = PACKAGE_DATA / "ur10-ipa" / "robot.yaml"
PANDA_MDH = PACKAGE_DATA / "panda-mukca" / "robot.yaml"


def pinocchio_frame(urdf_text: str, frame: str, q: np.ndarray) -> np.ndarray:
    """World pose (4x4) of ``frame`` by pinocchio's URDF parser (extra joints at zero)."""
    model = pin.buildModelFromXML(urdf_text)
    data = model.createData()
    full = np.zeros(model.nq)
    full[:len(q)] = q
    pin.framesForwardKinematics(model, data, full)
    return data.oMf[model.getFrameId(frame)].homogeneous


@pytest.fixture
def ur10(tmp_path):
    return write(tmp_path, "ur10.urdf", ur10_urdf())


@pytest.fixture
def panda(tmp_path):
    return write(tmp_path, "panda.urdf", panda_urdf())


@pytest.mark.parametrize("which, tip", [("ur10", "tool0"), ("panda", "panda_hand"),
                                        ("panda", "panda_link7")], ids=["ur10", "hand", "link7"])
def test_chain_matches_pinocchio_urdf_parser(which, tip, tmp_path):
    text = ur10_urdf() if which == "ur10" else panda_urdf()
    robot = load_robot(write(tmp_path, f"{which}.urdf", text), tip_link=tip)
    kinematics = Kinematics(robot)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(robot.lower_limits.clip(-3), robot.upper_limits.clip(None, 3))
        ours = kinematics.flange_poses(q)[0]
        assert np.abs(ours - pinocchio_frame(text, tip, q)).max() < 1e-12


def test_urdf_chains_match_the_dh_files(ur10, panda):
    """ur_description's tool0 is the UR10 DH flange (base turned half a turn); the Panda's
    link7 is its modified-DH flange."""
    rng = np.random.default_rng(4)
    for urdf_path, dh_path, tip in ((ur10, UR10_DH, "tool0"), (panda, PANDA_MDH, "panda_link7")):
        urdf, dh = load_robot(urdf_path, tip_link=tip), load_robot(dh_path)
        Q = rng.uniform(-1.5, 1.5, (6, dh.dof))
        Q[:, 3] = -1.0 if dh.dof == 7 else Q[:, 3]
        difference = Kinematics(urdf).flange_poses(Q) - Kinematics(dh).flange_poses(Q)
        assert np.abs(difference).max() < 1e-9  # ur_description's 1e-11 m roundings


def test_fixed_joints_fold_into_origins_and_flange(ur10, panda):
    ur = load_robot(ur10, tip_link="tool0")
    assert [j.name for j in ur.joints] == ["shoulder_pan_joint", "shoulder_lift_joint",
                                           "elbow_joint", "wrist_1_joint", "wrist_2_joint",
                                           "wrist_3_joint"]
    assert ur.joints[0].origin.xyz == (0.0, 0.0, 0.1273)  # base_link_inertia composed in
    assert ur.joints[0].origin.rpy[2] == pytest.approx(np.pi)
    hand = load_robot(panda, tip_link="panda_hand")
    assert hand.flange.xyz == pytest.approx((0, 0, 0.107))
    assert hand.flange.rpy == pytest.approx((0, 0, -np.pi / 4))
    # link7, link8 and the hand (0.74 + 0 + 0.73 kg) lumped in the hand's frame
    assert hand.joints[-1].mass == pytest.approx(1.47)
    com_link7 = (0.74 * np.array([0.01, -0.004, 0.06]) + 0.73 * np.array([0, 0, 0.107 + 0.04])
                 ) / 1.47
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    in_hand = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ (com_link7 - [0, 0, 0.107])
    assert np.allclose(hand.joints[-1].com, in_hand)
    assert hand.joints[3].limits == (-3.0718, -0.0698)


def test_branching_tree_is_refused_with_its_leaves(panda, tmp_path, capsys):
    with pytest.raises(InputError, match="branches into 2 leaves .*panda_leftfinger.*"
                                         "panda_rightfinger.*tip_link"):
        load_robot(panda)
    joints = tmp_path / "joints.csv"
    joints.write_text("q1,q2,q3,q4,q5,q6,q7\n0,0,0,-1,0,1,0\n")
    assert main(["fk", str(panda), str(joints), "--out", str(tmp_path / "poses.csv")]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "panda_leftfinger" in error
    assert not (tmp_path / "poses.csv").exists()


def test_broken_urdf_is_one_line(tmp_path):
    bad = write(tmp_path, "bad.urdf", ur10_urdf().replace('type="revolute"', 'type="floating"', 1))
    with pytest.raises(InputError, match="shoulder_pan_joint.*floating"):
        load_robot(bad, tip_link="tool0")
    broken = write(tmp_path, "broken.urdf", ur10_urdf()[:400])
    with pytest.raises(InputError, match="line"):
        load_robot(broken)
    with pytest.raises(InputError, match="no link 'tool9'"):
        load_robot(write(tmp_path, "ur.urdf", ur10_urdf()), tip_link="tool9")


def test_wide_urdf_limits_are_the_vendors_not_degrees(tmp_path):
    """A URDF is in radians by definition: limits of three turns each way load as they
    are; the same limits in a robot file that declares rad are refused as degrees."""
    text = ur10_urdf().replace('lower="-6.283185307179586" upper="6.283185307179586"',
                               'lower="-18.84955592153876" upper="18.84955592153876"', 1)
    assert text != ur10_urdf()
    robot = load_robot(write(tmp_path, "wide.urdf", text), tip_link="tool0")
    assert robot.joints[0].limits == pytest.approx((-6 * np.pi, 6 * np.pi))
    dh = yaml.safe_load(UR10_DH.read_text())
    dh["units"] = {"length": "m", "angle": "rad"}
    for joint in dh["joints"]:
        joint.update(theta=0.0, alpha=0.0, limits=[-18.85, 18.85])
    with pytest.raises(InputError, match="looks like degrees"):
        robot_from_dict(dh)


def test_urdf_convention_robot_file_round_trips(ur10):
    robot = load_robot(ur10, tip_link="tool0")
    again = robot_from_dict(yaml.safe_load(yaml.safe_dump(robot_to_dict(robot))))
    assert again == robot
    assert again.urdf == robot.urdf


def _simulated_pair(folder: Path, dh_path: Path, urdf_text: str, tip: str, errors: dict,
                    seed: int):
    """A simulated tracker dataset of the DH robot, and the same table read through the
    URDF (whose tip link is the DH flange)."""
    sim = simulate(dh_path, "tracker_points", out_dir=folder, rows=50, noise=2e-5,
                   geometric_errors=errors, seed=seed, progress=False)
    write(folder, "robot.urdf", urdf_text)
    content = yaml.safe_load(sim.dataset_path.read_text())
    content.update(robot="robot.urdf", tip_link=tip)
    (folder / "urdf.yaml").write_text(yaml.safe_dump(content))
    return sim.dataset_path, folder / "urdf.yaml"


@pytest.mark.parametrize("dh_path, text, tip, errors", [
    (UR10_DH, ur10_urdf(), "tool0",
     {"a2": 4e-4, "d4": -3e-4, "alpha3": 5e-4, "theta5": -6e-4, "beta3": 4e-4}),
    (PANDA_MDH, panda_urdf(), "panda_link7",
     {"a4": 4e-4, "d5": -3e-4, "alpha3": 5e-4, "theta5": -6e-4}),
], ids=["ur10", "panda"])
def test_urdf_calibrates_as_well_as_the_dh_file(tmp_path, dh_path, text, tip, errors):
    fit_dh, fit_urdf = _simulated_pair(tmp_path / "fit", dh_path, text, tip, errors, 1)
    val_dh, val_urdf = _simulated_pair(tmp_path / "val", dh_path, text, tip, errors, 2)
    by_dh = calibrate([load_dataset(fit_dh)], [load_dataset(val_dh)], diagnose=False)
    by_urdf = calibrate([load_dataset(fit_urdf)], [load_dataset(val_urdf)], diagnose=False)
    assert by_urdf.robot_nominal.convention == "urdf"
    # both at the noise floor (2e-5 m per coordinate), the URDF no worse than DH
    assert by_urdf.validation.rms_geometric < 5e-5
    assert by_urdf.validation.rms_geometric <= by_dh.validation.rms_geometric * 1.05
    assert by_urdf.fit.rms_geometric <= by_dh.fit.rms_geometric * 1.05
    assert by_urdf.validation.rms_nominal > 5 * by_urdf.validation.rms_geometric
    # redundancy is normal: the unknown tracker frame takes joint 1's whole origin
    reasons = by_urdf.identifiability.unidentifiable
    assert all(f"{stem}1" in reasons for stem in ("x", "y", "z", "roll", "pitch", "yaw"))
    assert "instrument frame" in reasons["x1"]


# ----------------------------------------------------------------------------- export


def _calibrated_folder(tmp_path: Path, dataset: Path, name: str) -> Path:
    out = tmp_path / name
    assert main(["calibrate", str(dataset), "--out", str(out), "--no-diagnose",
                 "--no-report"]) == 0
    return out


def _export(folder: Path, *options: str) -> None:
    assert main(["export", str(folder), *options]) == 0


def _pin_frames(path: Path, names, q) -> list[np.ndarray]:
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    full = np.zeros(model.nq)
    full[:len(q)] = q
    pin.framesForwardKinematics(model, data, full)
    return [data.oMf[model.getFrameId(n)].homogeneous for n in names]


UR_ERRORS = {"a2": 4e-4, "d4": -3e-4, "alpha3": 5e-4, "theta5": -6e-4, "beta3": 4e-4,
             "theta2": 3e-4, "d5": 2e-4}


def test_urdf_calibration_exports_over_its_own_file(tmp_path, capsys):
    _, dataset = _simulated_pair(tmp_path / "data", UR10_DH, ur10_urdf(), "tool0", UR_ERRORS, 1)
    folder = _calibrated_folder(tmp_path, dataset, "result")
    out = tmp_path / "ur10_calibrated.urdf"
    _export(folder, "--urdf", str(out))
    calibrated = load_robot(folder / "robot_calibrated.yaml")
    text = out.read_text()
    # names, meshes, inertias, limits and comments as the user wrote them
    original = ur10_urdf()
    for kept in ("package://ur_description/meshes/ur10/visual/wrist3.dae", 'name="tool0"',
                 'name="base_link-base_link_inertia"', '<mass value="12.93"',
                 'effort="150"', "UR10, test copy"):
        assert kept in text and kept in original
    model = pin.buildModelFromUrdf(str(out))
    reference = pin.buildModelFromXML(original)
    assert list(model.names) == list(reference.names)
    assert [f.name for f in model.frames] == [f.name for f in reference.frames]
    assert np.allclose(model.lowerPositionLimit, reference.lowerPositionLimit)
    assert [i.mass for i in model.inertias] == pytest.approx([i.mass for i in reference.inertias])
    rng = np.random.default_rng(7)
    kinematics = Kinematics(calibrated)
    for _ in range(5):
        q = rng.uniform(-3, 3, 6)
        (tool0,) = _pin_frames(out, ["tool0"], q)
        assert np.abs(tool0 - kinematics.flange_poses(q)[0]).max() < 1e-9
    # the calibration changed the geometry: the export is not the original
    (before,) = _pin_frames(write(tmp_path, "orig.urdf", original), ["tool0"], np.ones(6))
    (after,) = _pin_frames(out, ["tool0"], np.ones(6))
    assert np.linalg.norm(before[:3, 3] - after[:3, 3]) > 1e-4


@pytest.mark.parametrize("dh_path, text, tip, errors", [
    (UR10_DH, ur10_urdf(), "tool0", UR_ERRORS),
    (PANDA_MDH, panda_urdf(), "panda_hand",
     {"a4": 4e-4, "d5": -3e-4, "alpha3": 5e-4, "theta5": -6e-4, "d7": 3e-4}),
], ids=["ur10-dh", "panda-mdh"])
def test_dh_calibration_exports_into_the_vendor_link_frames(tmp_path, dh_path, text, tip,
                                                             errors):
    dataset, _ = _simulated_pair(tmp_path / "data", dh_path, text, tip, errors, 1)
    folder = _calibrated_folder(tmp_path, dataset, "result")
    vendor = write(tmp_path, "vendor.urdf", text)
    out = tmp_path / "calibrated.urdf"
    _export(folder, "--urdf", str(out), "--like", str(vendor), "--tip-link", tip)
    calibrated = load_robot(folder / "robot_calibrated.yaml")
    nominal = load_robot(dh_path)
    # the tip link's fixed place on the DH flange, from the nominal robots
    q0 = np.zeros(nominal.dof)
    (tip_nominal,) = _pin_frames(vendor, [tip], q0)
    offset = np.linalg.inv(Kinematics(nominal).flange_poses(q0)[0]) @ tip_nominal
    kinematics = Kinematics(calibrated)
    rng = np.random.default_rng(8)
    for _ in range(5):
        q = rng.uniform(nominal.lower_limits.clip(-3), nominal.upper_limits.clip(None, 3))
        (ours,) = _pin_frames(out, [tip], q)
        assert np.abs(ours - kinematics.flange_poses(q)[0] @ offset).max() < 1e-9
    assert [f.name for f in pin.buildModelFromUrdf(str(out)).frames] == \
        [f.name for f in pin.buildModelFromXML(text).frames]


def test_vendor_file_of_another_arm_is_refused(tmp_path, capsys):
    dataset, _ = _simulated_pair(tmp_path / "data", UR10_DH, ur10_urdf(), "tool0", UR_ERRORS, 1)
    folder = _calibrated_folder(tmp_path, dataset, "result")
    other = write(tmp_path, "other.urdf", ur10_urdf().replace('xyz="-0.612 0 0"',
                                                              'xyz="-0.613 0 0"'))
    out = tmp_path / "x.urdf"
    assert main(["export", str(folder), "--urdf", str(out), "--like", str(other),
                 "--tip-link", "tool0"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "does not follow joint" in error
    assert not out.exists()


def test_ur_calibration_file(tmp_path):
    """The nominal UR10 gives ur_description's default kinematics values; a calibrated
    URDF robot gives the origins its exported URDF holds."""
    from robocal_casadi.urdf.writer import ur_calibration

    block = ur_calibration(load_robot(UR10_DH))["kinematics"]
    assert block["shoulder"] == pytest.approx({"x": 0, "y": 0, "z": 0.1273, "roll": 0,
                                               "pitch": 0, "yaw": 0}, abs=1e-12)
    assert block["upper_arm"]["roll"] == pytest.approx(np.pi / 2)
    assert block["forearm"]["x"] == pytest.approx(-0.612)
    assert (block["wrist_1"]["x"], block["wrist_1"]["z"]) == pytest.approx((-0.5723, 0.163941))
    assert (block["wrist_2"]["y"], block["wrist_2"]["roll"]) == pytest.approx((-0.1157, np.pi / 2))
    assert block["wrist_3"]["y"] == pytest.approx(0.0922)
    assert block["hash"].startswith("calib_")

    _, dataset = _simulated_pair(tmp_path / "data", UR10_DH, ur10_urdf(), "tool0", UR_ERRORS, 1)
    folder = _calibrated_folder(tmp_path, dataset, "result")
    kinematics_file, urdf_file = tmp_path / "ur10_calibration.yaml", tmp_path / "ur10.urdf"
    _export(folder, "--ur-calibration", str(kinematics_file), "--urdf", str(urdf_file))
    values = yaml.safe_load(kinematics_file.read_text())["kinematics"]
    # rebuild the URDF from the kinematics file the way ur_description does
    text = ur10_urdf()
    import xml.etree.ElementTree as ET
    root = ET.fromstring(text)
    for segment, joint in zip(("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2",
                               "wrist_3"),
                              ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                               "wrist_1_joint", "wrist_2_joint", "wrist_3_joint")):
        origin = root.find(f"joint[@name='{joint}']/origin")
        v = values[segment]
        origin.set("xyz", f"{v['x']!r} {v['y']!r} {v['z']!r}")
        origin.set("rpy", f"{v['roll']!r} {v['pitch']!r} {v['yaw']!r}")
    rebuilt = write(tmp_path, "rebuilt.urdf", ET.tostring(root, encoding="unicode"))
    q = np.array([0.3, -1.2, 1.1, -0.4, 1.3, 0.2])
    assert np.abs(_pin_frames(rebuilt, ["tool0"], q)[0]
                  - _pin_frames(urdf_file, ["tool0"], q)[0]).max() < 1e-12


# ----------------------------------------------------------------------------- DH equivalent


@pytest.mark.parametrize("text, tip", [(ur10_urdf(), "tool0"), (panda_urdf(), "panda_hand")],
                         ids=["ur10", "panda"])
def test_dh_equivalent_has_the_same_kinematics(tmp_path, text, tip):
    from robocal_casadi.urdf.equivalent import dh_equivalent

    robot = load_robot(write(tmp_path, "r.urdf", text), tip_link=tip)
    equivalent = dh_equivalent(robot)
    rng = np.random.default_rng(5)
    Q = rng.uniform(-2.5, 2.5, (8, robot.dof))
    for q in Q:
        ours = Kinematics(equivalent.robot).tool_poses(q)[0]
        assert np.abs(ours - pinocchio_frame(text, tip, q)).max() < 1e-12
    parallel = [i + 1 for i, j in enumerate(equivalent.robot.joints) if j.has_beta]
    if "ur10" in text:
        # axes 2, 3 and 4 are parallel: DH's a2, a3 and Hayati beta on joints 2 and 3
        assert parallel == [2, 3] and len(equivalent.notes) == 2
        assert sorted(abs(j.a) for j in equivalent.robot.joints)[-2:] == pytest.approx(
            [0.5723, 0.612])
    else:
        assert parallel == [] and equivalent.notes == ()


# A six-revolute arm of the common industrial design (axes 4, 5, 6 meeting in one wrist
# point, axis 4 perpendicular to axis 3): not a UR.
SPHERICAL_WRIST = {
    "name": "spherical-wrist-6r", "convention": "dh", "units": {"length": "mm", "angle": "deg"},
    "joints": [
        {"type": "revolute", "theta": 0, "d": 400, "a": 25, "alpha": -90, "limits": [-170, 170]},
        {"type": "revolute", "theta": -90, "d": 0, "a": 455, "alpha": 0, "limits": [-90, 150]},
        {"type": "revolute", "theta": 0, "d": 0, "a": 35, "alpha": -90, "limits": [-200, 80]},
        {"type": "revolute", "theta": 0, "d": 420, "a": 0, "alpha": 90, "limits": [-185, 185]},
        {"type": "revolute", "theta": 0, "d": 0, "a": 0, "alpha": -90, "limits": [-120, 120]},
        {"type": "revolute", "theta": 0, "d": 80, "a": 0, "alpha": 0, "limits": [-350, 350]}],
}


def test_ur_structure_is_read_from_the_axes(ur10):
    """The UR10 passes in DH and URDF form and after a calibration-sized change; an arm
    with a spherical wrist, the Panda and a UR10 whose elbow twists do not."""
    from robocal_casadi.urdf.writer import ur_structure_problem

    ur = load_robot(UR10_DH)
    assert ur_structure_problem(ur) is None
    assert ur_structure_problem(load_robot(ur10, tip_link="tool0")) is None
    values = ur.parameter_vector()
    names = ur.parameters().names
    nudged = values.copy()
    for name, change in (("alpha3", np.radians(0.3)), ("a4", 2e-3), ("d5", -1e-3)):
        nudged[names.index(name)] += change
    assert ur_structure_problem(ur.with_parameters(nudged)) is None
    twisted = values.copy()
    twisted[names.index("alpha2")] += np.radians(30)
    assert "not parallel" in ur_structure_problem(ur.with_parameters(twisted))
    assert "not parallel" in ur_structure_problem(robot_from_dict(SPHERICAL_WRIST))
    assert "six revolute" in ur_structure_problem(load_robot(PANDA_MDH))


def _bare_folder(folder: Path, content: dict) -> Path:
    """A calibration folder holding only a robot file and a result.json without changes."""
    folder.mkdir()
    (folder / "robot_calibrated.yaml").write_text(yaml.safe_dump(content))
    (folder / "result.json").write_text('{"parameters": []}')
    return folder


def test_ur_calibration_export_refuses_other_arms(tmp_path, capsys):
    """--ur-calibration writes for a UR arm and refuses another six-joint arm in one line,
    exit 2, nothing written."""
    other = _bare_folder(tmp_path / "other", SPHERICAL_WRIST)
    out = tmp_path / "other.yaml"
    assert main(["export", str(other), "--ur-calibration", str(out)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "not a UR arm" in error and "--ur-calibration" in error
    assert not out.exists()
    ur = _bare_folder(tmp_path / "ur", yaml.safe_load(UR10_DH.read_text()))
    out = tmp_path / "ur.yaml"
    assert main(["export", str(ur), "--ur-calibration", str(out)]) == 0
    assert set(yaml.safe_load(out.read_text())["kinematics"]) >= {"shoulder", "wrist_3"}


def test_exported_urdf_carries_the_robot_files_masses_with_valid_inertias(tmp_path):
    """The shipped UR10 file gives each link a mass [kg] and a centre of mass [mm]: the URDF
    written from it holds those (in SI), an inertia tensor a physics engine accepts
    (positive definite, the triangle inequalities) and says which values are stand-ins."""
    import xml.etree.ElementTree as ET

    from robocal_casadi.model.pinocchio_model import LINK_DENSITY, urdf_text

    given = yaml.safe_load(UR10_DH.read_text())
    assert given["units"]["length"] == "mm"
    text = urdf_text(load_robot(UR10_DH))
    assert "stand-in" in text
    root = ET.fromstring(text)
    links = {link.get("name"): link for link in root.iter("link")}
    for i, joint in enumerate(given["joints"], start=1):
        inertial = links[f"frame_{i}"].find("inertial")
        assert float(inertial.find("mass").get("value")) == joint["mass"]
        com = [float(v) for v in inertial.find("origin").get("xyz").split()]
        np.testing.assert_allclose(com, np.array(joint["com"]) * 1e-3, rtol=1e-15, atol=1e-15)
        tensor = inertial.find("inertia")
        inertia = np.array([[float(tensor.get(f"i{min(a, b)}{max(a, b)}")) for b in "xyz"]
                            for a in "xyz"])
        principal = np.linalg.eigvalsh(inertia)
        assert principal.min() > 0
        for k in range(3):
            assert principal[k] <= principal[k - 1] + principal[k - 2]
        # a solid sphere of the stated density: I = 2/5 m r^2, m = 4/3 pi r^3 rho
        radius = np.sqrt(2.5 * principal[0] / joint["mass"])
        assert 4.0 / 3.0 * np.pi * radius**3 * LINK_DENSITY == pytest.approx(joint["mass"])
    model = pin.buildModelFromXML(text)
    assert sum(inertia.mass for inertia in model.inertias) == pytest.approx(
        sum(j["mass"] for j in given["joints"]))
