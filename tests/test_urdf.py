"""URDF robots: the chain read from a URDF file against pinocchio's own URDF parser, the
DH files of the same robots, and calibration on simulated data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from robocal_casadi.calibration import calibrate
from robocal_casadi.cli import main
from robocal_casadi.datasets import load_dataset
from robocal_casadi.errors import InputError
from robocal_casadi.kinematics import Kinematics
from robocal_casadi.robot import load_robot, robot_from_dict, robot_to_dict
from robocal_casadi.simulate import simulate
from urdf_robots import panda_urdf, ur10_urdf, write

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
