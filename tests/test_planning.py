"""Experiment design: indices against closed forms, plans that the robot can run, designed
plans better than random ones, the engine's own judgement of a plan, and clear refusals."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from planning import design_plan, engine_identifiability, index_of_jacobian, index_value, write_plan
from planning.indices import better, canonical, maximise, scale_columns
from robocal_casadi.cli import main
from robocal_casadi.common.table import read_table
from robocal_casadi.errors import InputError
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.model.examples import industrial_6r, panda_7dof
from robocal_casadi.model.kinematics import Kinematics
from robocal_casadi.model.robot import save_robot

# ----------------------------------------------------------------------------- indices


def _matrix_with_singular_values(s, rows=7, seed=0):
    rng = np.random.default_rng(seed)
    U, _ = np.linalg.qr(rng.normal(size=(rows, rows)))
    V, _ = np.linalg.qr(rng.normal(size=(len(s), len(s))))
    return U[:, :len(s)] @ np.diag(s) @ V.T


def test_indices_match_closed_forms_on_a_hand_made_matrix():
    s = np.array([4.0, 2.0, 1.0, 0.5])
    J = _matrix_with_singular_values(s)
    expected = {
        "O1": (4 * 2 * 1 * 0.5) ** (1 / 4),  # geometric mean, exponent 1/m
        "O2": 4.0 / 0.5,  # of J, not J^T J (which would give 64)
        "O3": 0.5,
        "O4": 0.5**2 / 4.0,
        "O5": 1.0 / (1 / 4 + 1 / 2 + 1 / 1 + 1 / 0.5),
    }
    for name, value in expected.items():
        assert index_of_jacobian(name, J, scaled=False) == pytest.approx(value, rel=1e-12)
    assert index_of_jacobian("cond", J, scaled=False) == pytest.approx(8.0, rel=1e-12)


def test_index_directions_and_rank_deficiency():
    assert canonical("cond") == "O2"
    assert not maximise("cond") and all(maximise(k) for k in ("O1", "O3", "O4", "O5"))
    assert better("O2", 10.0, 20.0) and better("O3", 2.0, 1.0)
    assert index_value("O2", [1.0, 0.0]) == np.inf
    assert index_value("O1", [1.0, 0.0]) == 0.0
    with pytest.raises(ValueError, match="O5"):
        canonical("O6")


def test_column_scaling_removes_units():
    J = _matrix_with_singular_values(np.array([3.0, 1.0, 0.2]))
    units = np.diag([1e3, 1.0, 1e-3])  # e.g. mm, m and km columns
    assert index_of_jacobian("O2", J @ units) == pytest.approx(index_of_jacobian("O2", J),
                                                               rel=1e-9)
    assert np.allclose(np.linalg.norm(scale_columns(J @ units), axis=0), 1.0)


# ----------------------------------------------------------------------------- set-ups


@pytest.fixture(scope="module")
def setups(tmp_path_factory):
    folder = tmp_path_factory.mktemp("plan")
    save_robot(industrial_6r(), folder / "r6.yaml")
    save_robot(panda_7dof(), folder / "p7.yaml")
    mm, m = dict(length="mm", angle="deg"), dict(length="m", angle="rad")
    files = {
        "tracker_6r": dict(kind="tracker_points", robot="r6.yaml", units=mm,
                           target=dict(xyz=[0, 0, 100]), instrument=dict(xyz=[2500, 0, 800])),
        "tracker_7": dict(kind="tracker_points", robot="p7.yaml", units=m,
                          target=dict(xyz=[0, 0, 0.1]), instrument=dict(xyz=[2.0, 0.5, 0.6])),
        "bar_6r": dict(kind="cross_bar", robot="r6.yaml", units=mm,
                       bar=dict(length=400), probe=dict(xyz=[0, 0, 150])),
        "bar_7": dict(kind="cross_bar", robot="p7.yaml", units=m,
                      bar=dict(length=0.3), probe=dict(xyz=[0, 0, 0.1])),
        "sphere_6r": dict(kind="sphere_laser", robot="r6.yaml", units=mm,
                          sphere=dict(radius=25, centre_guess=[900, 100, 300]),
                          laser=dict(origin_guess=[60, -15, 140], direction_guess=[0, 0, 1])),
        "artifact_7": dict(kind="artifact_touches", robot="p7.yaml", units=m,
                           probe=dict(xyz=[0, 0, 0.1335]),
                           artifact=dict(distances=[["hole_0", "hole_1", 0.05]]),
                           planning=dict(touches_per_socket=3)),
        "far_sphere": dict(kind="sphere_laser", robot="r6.yaml", units=mm,
                           sphere=dict(radius=25, centre_guess=[9000, 0, 300]),
                           laser=dict(origin_guess=[60, -15, 140], direction_guess=[0, 0, 1])),
        "long_bar": dict(kind="cross_bar", robot="r6.yaml", units=mm,
                         bar=dict(length=6000), probe=dict(xyz=[0, 0, 150])),
    }
    paths = {}
    for name, content in files.items():
        content["data"] = f"{name}.csv"  # the table does not exist yet
        paths[name] = folder / f"{name}.yaml"
        paths[name].write_text(yaml.safe_dump(content))
    return paths


PLANS: dict = {}
POOL = {"tracker_6r": 150, "tracker_7": 150, "bar_6r": 60, "bar_7": 60, "sphere_6r": 150,
        "artifact_7": 40}
COUNT = {"tracker_6r": 30, "tracker_7": 30, "bar_6r": 12, "bar_7": 12, "sphere_6r": 30,
         "artifact_7": 8}


def _plan(setups, name):
    """The designed plan of set-up ``name`` (made once per test session)."""
    if name not in PLANS:
        dataset = load_dataset(setups[name], require_data=False)
        PLANS[name] = (dataset, design_plan(dataset, COUNT[name], "cond", seed=1,
                                            pool=POOL[name], refine=False, quiet=True))
    return PLANS[name]


def _table(setups, name, tmp_path):
    """The plan written as a table and read back, with its dataset."""
    dataset, plan = _plan(setups, name)
    write_plan(plan, tmp_path / "plan.csv")
    return dataset, read_table(tmp_path / "plan.csv")


def _plan_via_cli(path, count, out, *extra):
    assert main(["plan", str(path), "--count", str(count), "--out", str(out), "--no-refine",
                 *extra]) == 0
    return read_table(out)


def _joints(table, dataset):
    scales = np.array([dataset.units.angle_scale if j.revolute else dataset.units.length_scale
                       for j in dataset.robot.joints])
    names = [f"q{i}" for i in range(1, dataset.robot.dof + 1)]
    return np.column_stack([table.numbers(n) for n in names]) * scales


def _above_table_and_within_limits(dataset, Q, points):
    robot = dataset.robot
    assert np.all(Q >= robot.lower_limits) and np.all(Q <= robot.upper_limits)
    kin = Kinematics(robot)
    for q in Q:
        frames = kin.joint_frames(q, kin.nominal)
        assert all(float(frames[i][2, 3]) > robot.base.xyz[2] for i in range(1, robot.dof + 1))
    assert np.all(points[:, 2] > robot.base.xyz[2])


# ----------------------------------------------------------------------------- tracker


@pytest.mark.parametrize("name", ["tracker_6r", "tracker_7"])
def test_tracker_plan_is_runnable_and_visible(setups, tmp_path, name):
    dataset, table = _table(setups, name, tmp_path)
    joints = tuple(f"q{i}" for i in range(1, dataset.robot.dof + 1))
    assert table.columns == joints + ("x", "y", "z")
    assert len(table) == 30 and all(c == "" for c in table.text("x"))
    Q = _joints(table, dataset)
    kin = Kinematics(dataset.robot)
    poses = kin.flange_poses(Q)
    targets = poses[:, :3, :3] @ dataset.target + poses[:, :3, 3]
    _above_table_and_within_limits(dataset, Q, targets)
    towards = dataset.instrument - targets
    towards /= np.linalg.norm(towards, axis=1, keepdims=True)
    angle = np.degrees(np.arccos(np.einsum("ni,ni->n", poses[:, :3, 2], towards)))
    assert np.all(angle < 60.0)


def test_plan_command_writes_the_table_and_a_summary(setups, tmp_path, capsys):
    table = _plan_via_cli(setups["tracker_6r"], 20, tmp_path / "plan.csv", "--index", "O3",
                          "--seed", "4")
    assert len(table) == 20 and table.columns[-3:] == ("x", "y", "z")
    out = capsys.readouterr().out
    assert "O3 (smallest singular value)" in out and "median" in out and "wrote" in out


# ----------------------------------------------------------------------------- bars


@pytest.mark.parametrize("name", ["bar_6r", "bar_7"])
def test_bar_plan_puts_the_probe_on_the_planned_sockets(setups, tmp_path, name):
    dataset, table = _table(setups, name, tmp_path)
    assert table.columns[:2] == ("pose", "point") and table.columns[-3:] == (
        "socket_x", "socket_y", "socket_z")
    poses = table.numbers("pose").astype(int)
    points = table.text("point")
    assert sorted(set(poses)) == list(range(1, COUNT[name] + 1))
    for pose in set(poses):
        assert sorted(points[i] for i in np.flatnonzero(poses == pose)) == ["A", "B", "C", "D"]
    Q = _joints(table, dataset)
    sockets = np.column_stack([table.numbers(f"socket_{k}") for k in "xyz"])
    sockets *= dataset.units.length_scale
    probe = Kinematics(dataset.robot).points(Q, dataset.probe)
    assert np.max(np.linalg.norm(probe - sockets, axis=1)) < 1e-6
    _above_table_and_within_limits(dataset, Q, sockets)
    # the sockets of each placement form the cross: |AC| = |BD| = L, AC perpendicular to BD
    L = dataset.distances[0][2]
    for pose in set(poses):
        s = {points[i]: sockets[i] for i in np.flatnonzero(poses == pose)}
        assert np.linalg.norm(s["C"] - s["A"]) == pytest.approx(L, abs=1e-9)
        assert np.linalg.norm(s["D"] - s["B"]) == pytest.approx(L, abs=1e-9)
        assert abs(np.dot(s["C"] - s["A"], s["D"] - s["B"])) < 1e-12


def test_unreachable_bar_is_refused_with_a_clear_message(setups, tmp_path, capsys):
    out = tmp_path / "plan.csv"
    assert main(["plan", str(setups["long_bar"]), "--count", "10", "--out", str(out)]) == 2
    message = capsys.readouterr().err
    assert "bar.length" in message and "reach" in message and "long_bar.yaml" in message
    assert not out.exists()


def test_sphere_out_of_reach_is_refused(setups):
    dataset = load_dataset(setups["far_sphere"], require_data=False)
    with pytest.raises(InputError, match="out of reach") as error:
        design_plan(dataset, 20, refine=False, quiet=True)
    assert "sphere.centre_guess" in str(error.value)


def test_too_few_readings_are_refused(setups):
    dataset = load_dataset(setups["tracker_6r"], require_data=False)
    with pytest.raises(InputError, match="too few"):
        design_plan(dataset, 4, refine=False, quiet=True)


# ----------------------------------------------------------------------------- quality


@pytest.mark.parametrize("name", ["tracker_6r", "bar_6r", "tracker_7", "bar_7", "artifact_7"])
def test_designed_plan_beats_random_plans_and_matches_the_engine(setups, name):
    dataset, plan = _plan(setups, name)
    assert plan.value < plan.random_median
    # the calibration engine, from the plan as a dataset, sees the same Jacobian
    judged = engine_identifiability(dataset, plan.candidates, plan.identifiable)
    assert judged.identifiable == plan.identifiable
    assert np.allclose(judged.singular_values, plan.singular_values, rtol=1e-8, atol=1e-9)
    assert judged.condition_number == pytest.approx(plan.value, rel=1e-6)


def test_each_index_is_improved_by_its_own_design(setups):
    dataset = load_dataset(setups["tracker_6r"], require_data=False)
    for index in ("O1", "O3", "O4", "O5"):
        plan = design_plan(dataset, 25, index, seed=2, pool=100, refine=False, quiet=True)
        assert plan.index == index
        assert better(index, plan.value, plan.random_median)


def test_refinement_keeps_the_plan_runnable_and_does_not_worsen_it(setups):
    dataset = load_dataset(setups["bar_6r"], require_data=False)
    plain = design_plan(dataset, 10, seed=3, pool=40, refine=False, quiet=True)
    refined = design_plan(dataset, 10, seed=3, pool=40, refine=True, refine_rounds=1, quiet=True)
    assert refined.value <= plain.value
    probe = Kinematics(dataset.robot).points(refined.joints, dataset.probe)
    sockets = np.array([c.sockets[p] for c in refined.candidates for p in c.points])
    assert np.max(np.linalg.norm(probe - sockets, axis=1)) < 1e-6


# ----------------------------------------------------------------------------- sphere, artifact


def test_sphere_plan_beams_hit_the_sphere_within_range(setups, tmp_path):
    dataset, table = _table(setups, "sphere_6r", tmp_path)
    assert table.columns[-1] == "distance" and all(c == "" for c in table.text("distance"))
    Q = _joints(table, dataset)
    poses = Kinematics(dataset.robot).flange_poses(Q)
    o = poses[:, :3, :3] @ dataset.origin_guess + poses[:, :3, 3]
    d = poses[:, :3, :3] @ dataset.direction_guess
    v = o - dataset.centre_guess
    b = np.einsum("ni,ni->n", d, v)
    disc = b**2 - (np.einsum("ni,ni->n", v, v) - dataset.radius**2)
    assert np.all(disc > 0)  # the beam line meets the sphere
    reading = -b - np.sqrt(disc)
    assert np.all((reading >= 0.05 - 1e-9) & (reading <= 0.30 + 1e-9))
    _above_table_and_within_limits(dataset, Q, o)
    plan = _plan(setups, "sphere_6r")[1]
    assert plan.value < plan.random_median
    # the engine's model (beam as a 3-vector with a unit-length row) sees the same conditioning
    judged = engine_identifiability(dataset, plan.candidates)
    assert len(judged.identifiable) == len(plan.identifiable) + 1
    assert judged.condition_number == pytest.approx(plan.value, rel=1e-6)


def test_artifact_plan_touches_each_socket_in_several_configurations(setups, tmp_path):
    dataset, table = _table(setups, "artifact_7", tmp_path)
    poses, points = table.numbers("pose").astype(int), table.text("point")
    assert len(table) == 8 * 2 * 3
    Q = _joints(table, dataset)
    sockets = np.column_stack([table.numbers(f"socket_{k}") for k in "xyz"])
    probe = Kinematics(dataset.robot).points(Q, dataset.probe)
    assert np.max(np.linalg.norm(probe - sockets, axis=1)) < 1e-6
    for pose in set(poses):
        rows = np.flatnonzero(poses == pose)
        by_socket = {points[i]: sockets[i] for i in rows}
        spacing = np.linalg.norm(by_socket["hole_0"] - by_socket["hole_1"])
        assert spacing == pytest.approx(0.05, abs=1e-9)
        for socket in ("hole_0", "hole_1"):
            configurations = Q[[i for i in rows if points[i] == socket]]
            assert len(configurations) == 3
            assert np.min(np.ptp(configurations, axis=0).max()) > 1e-3  # really different


def test_reference_scaling_keeps_size_and_design_scaling_does_not(setups):
    """O2 normalises each design's columns (scale-free, as the engine does); the other
    indices use fixed reference scales, so a design repeated twice scores higher."""
    from planning.information import Information
    from planning.rows import RowModel

    dataset, plan = _plan(setups, "tracker_6r")
    kinematics = Kinematics(dataset.robot)
    rows = RowModel(plan.setup, kinematics)
    info = Information(rows.blocks(list(plan.candidates)), rows.parameters, rows.shared)
    once = list(range(len(plan.candidates)))
    twice = once + once
    for_design = [info.spectrum(d, "design") for d in (once, twice)]
    for_reference = [info.spectrum(d, "reference") for d in (once, twice)]
    assert np.allclose(for_design[0], for_design[1])  # unit columns: repetition changes nothing
    assert np.allclose(for_reference[1], np.sqrt(2) * for_reference[0])  # twice the information
    # the batched eigenvalue route gives the same singular values as the SVD route
    for mode in ("design", "reference"):
        batched = info.spectra(info.matrices[once].sum(axis=0)[None], mode)[0]
        assert np.allclose(batched, info.spectrum(once, mode), rtol=1e-6)


def test_a_dataset_pointing_at_an_unmeasured_plan_can_be_planned_again(tmp_path):
    """The set-up is what matters: a table with empty measured columns is not read."""
    from robocal_casadi.instruments.simulate import simulate as write_simulated

    sim = write_simulated(industrial_6r(), "tracker_points", out_dir=tmp_path / "sim", rows=30,
                          seed=1, progress=False)
    first = tmp_path / "sim" / "plan.csv"
    assert main(["plan", str(sim.dataset_path), "--count", "12", "--out", str(first),
                 "--no-refine"]) == 0
    text = sim.dataset_path.read_text().replace("data: points.csv", "data: plan.csv")
    sim.dataset_path.write_text(text)
    second = tmp_path / "plan2.csv"
    assert main(["plan", str(sim.dataset_path), "--count", "12", "--out", str(second),
                 "--no-refine"]) == 0
    assert second.read_text().splitlines()[0] == first.read_text().splitlines()[0]
