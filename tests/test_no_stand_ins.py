"""No stand-ins: a physical effect is named only where it explains its own pattern.

Beside a learned map (``calibration.covered``): a physical effect added before the map, on
a joint the map follows, is judged again with the map in and goes when the map covers what
it explained; a real one stays. Truths are computed here through pinocchio (geometry off
the drawing, play from the row order, an error no library effect describes), not by the
code under test.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from robocal_casadi import load_dataset
from robocal_casadi.calibration import calibrate
from robocal_casadi.calibration.covered import judge
from robocal_casadi.calibration.learned import MapFolds
from robocal_casadi.commands.calibrate import summary
from robocal_casadi.model.examples import ROBOTS
from robocal_casadi.model.kinematics import Kinematics
from robocal_casadi.model.pinocchio_model import frame_placements, pinocchio_model
from robocal_casadi.model.robot import save_robot
from robocal_casadi.results import Decision

NOISE = 1e-5  # [m] per tracker coordinate
TARGET = np.array([0.0, 0.0, 0.1])  # [m] reflector in the flange frame


def shift_over_q2(Q: np.ndarray) -> np.ndarray:
    """A world-frame error of the tool (N x 3) [m] that follows joint 2's reading alone, in
    steps no library effect describes (0.1 mm)."""
    q2 = Q[:, 1]
    return 1e-4 * np.column_stack([np.tanh((q2 - 0.3) / 0.4), 0.3 * np.exp(-q2 ** 2),
                                   0.6 * np.tanh((q2 + 0.5) / 0.3)])


def directions(Q: np.ndarray) -> np.ndarray:
    """Each joint's direction of motion per row (N x dof): the sign of its last change in
    row order, 0 until it first moves."""
    out = np.zeros(Q.shape)
    for k in range(1, len(Q)):
        step = np.sign(Q[k] - Q[k - 1])
        out[k] = np.where(step != 0, step, out[k - 1])
    return out


def tracker(folder: Path, rows: int, seed: int, play2: float = 0.0) -> object:
    """Tracker data of the 6R arm, its DH parameters off the drawing by 0.5 mm / 0.5 mrad
    (fixed), joint 2 trailing its reading by ``play2 / 2`` [rad] against its direction of
    motion, plus ``shift_over_q2``; the tracker frame is the world frame."""
    robot = ROBOTS["industrial_6r"]()
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    Q = rng.uniform(np.maximum(robot.lower_limits, -math.pi) * 0.9,
                    np.minimum(robot.upper_limits, math.pi) * 0.9, (rows, robot.dof))
    kinematics = Kinematics(robot)
    p = kinematics.nominal.copy()
    drawing = np.random.default_rng(700)
    for i in range(1, robot.dof + 1):
        for stem in ("theta", "d", "a", "alpha"):
            p[kinematics.registry.index(f"{stem}{i}")] += drawing.normal(0.0, 5e-4)
    model = pinocchio_model(robot.with_parameters(p), with_links=False)
    arm = Q.copy()
    arm[:, 1] -= 0.5 * play2 * directions(Q)[:, 1]
    points = np.array([(lambda T: T[:3, :3] @ TARGET + T[:3, 3])(
        frame_placements(model, q, ["flange"])[0]) for q in arm])
    points += rng.normal(0.0, NOISE, points.shape) + shift_over_q2(Q)
    save_robot(robot, folder / "robot.yaml")
    (folder / "dataset.yaml").write_text(
        "kind: tracker_points\nrobot: robot.yaml\nunits: {length: m, angle: rad}\n"
        "target: {xyz: [0.0, 0.0, 0.1]}\ndata: points.csv\n")
    header = ",".join([f"q{j + 1}" for j in range(robot.dof)] + ["x", "y", "z"])
    lines = [header] + [",".join(repr(float(v)) for v in row)
                        for row in np.column_stack([Q, points])]
    (folder / "points.csv").write_text("\n".join(lines) + "\n")
    return load_dataset(folder / "dataset.yaml")


def test_a_stand_in_beside_the_map_goes(tmp_path):
    """The error follows q2 alone: a periodic error of joint 1 takes a sliver of it first;
    the map over the joints the structure follows holds the whole pattern, and with it in,
    the periodic error no longer pays and is taken out, the terminal saying why."""
    result = calibrate([tracker(tmp_path / "fit", 300, 1)], [tracker(tmp_path / "val", 150, 2)])
    maps = [e for e in result.effects if e.name == "residual_map"]
    assert maps and 2 in maps[0].joints, [e.summary for e in result.effects]
    early = [t for t in result.diagnosis if t.outcome is Decision.ADDED]
    gone = [t for t in result.diagnosis if t.outcome is Decision.COVERED]
    assert early, "diagnosis added no physical effect before the map: the case tests nothing"
    assert {t.label for t in gone} == {t.label for t in early}, \
        [t.decision for t in result.diagnosis if t.outcome is not Decision.NOT_PAYING]
    assert [e.name for e in result.effects] == ["residual_map"]
    for test in gone:
        assert set(test.joints) & set(maps[0].joints)
        assert test.decision.startswith("removed: the learned map over q")
    lines = [line for line in summary(result).splitlines() if line.startswith("taken out once")]
    assert len(lines) == 1 and all(t.label in lines[0] for t in gone), lines
    # the model left is what the held-out data confirm: the map alone lowers their error
    assert result.validation.rms_final < 0.5 * result.validation.rms_geometric, result.validation


def test_real_play_survives_the_map(tmp_path):
    """The same error plus 0.03 deg of play in joint 2: a map over joint readings cannot
    follow the direction of motion, so the play is judged again beside the map and stays,
    with its size."""
    play = math.radians(0.03)
    result = calibrate([tracker(tmp_path / "fit", 300, 1, play)],
                       [tracker(tmp_path / "val", 150, 2, play)])
    maps = [e for e in result.effects if e.name == "residual_map"]
    assert maps and 2 in maps[0].joints, [e.summary for e in result.effects]
    play_found = [e for e in result.effects if e.name == "backlash"]
    assert play_found and play_found[0].joints == (2,), [e.summary for e in result.effects]
    assert not [t for t in result.diagnosis
                if t.outcome is Decision.COVERED and t.effect == "backlash"]
    # its standard error from the fit's noise: within a few of them, and 10% at most
    assert abs(play_found[0].parameters["b2"] - play) < 0.1 * play, play_found[0].parameters


def folds(random: float, extrapolating: tuple[float, ...], fit: float,
          reason: str = "") -> MapFolds:
    """Held-out squared errors [m^2] with a map: the random scheme's, then one per
    extrapolating scheme (tolerance 2%); 100 errors."""
    schemes = (("units", False, 0.02),) + tuple((f"q{k + 1} ranges", True, 0.02)
                                                 for k in range(len(extrapolating)))
    with_map = np.array((random,) + extrapolating)
    return MapFolds(with_map * 2, with_map, fit, schemes, 100, reason)


def test_a_unit_beside_the_map_pays_by_the_rules_diagnosis_adds_effects_by():
    n, k = 300, 2
    without = folds(1.0, (1.0, 1.0), fit=1.0)
    # 5% lower held out, every region lower, a BIC drop of n log(1/0.9) - k log n > 10
    assert judge(folds(0.95 ** 2, (0.9, 0.9), fit=0.9), without, k, n).reason == ""
    # within 1% of the model without it beside its own map: covered
    slight = judge(folds(0.995 ** 2, (0.9, 0.9), fit=0.9), without, k, n)
    assert slight.reason.startswith("held-out RMS") and "needs -1%" in slight.reason
    # the fit barely falls: the BIC drop n log(1/0.99) - 2 log 300 is below 10
    assert judge(folds(0.9, (0.9, 0.9), fit=0.99), without, k, n).reason.startswith("BIC")
    # one region grown by 5% (tolerance 2%): does not extrapolate
    grown = judge(folds(0.9, (1.05, 0.5), fit=0.9), without, k, n)
    assert grown.reason.startswith("does not extrapolate") and "q1 ranges" in grown.reason
    # no map pays without it: nothing covers it, it stays whatever its numbers
    alone = folds(1.0, (1.0, 1.0), fit=1.0, reason="held-out RMS -0.2% (needs -1%)")
    assert judge(folds(1.0, (1.0, 1.0), fit=1.0), alone, k, n).reason == ""
