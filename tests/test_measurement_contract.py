"""The contract every registered measurement model keeps, checked on simulated truth.

Parametrised over the instrument registry (``robocal_casadi.instruments``): a model
added to the registry is checked here too (and fails until the truth file's values for
its unknowns are read below). Each kind is simulated without noise; the residual
evaluated by the engine at the true values written to ``truth.yaml`` must vanish, the
engine's Jacobian must match central differences of its residual, and shapes and units
must agree with what the model declares.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal_casadi.calibration import Problem
from robocal_casadi.instruments import INSTRUMENTS, MeasurementModel, model_for
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import industrial_6r
from robocal_casadi.model.transforms import invert, pose_from_xyz_rpy

ROOT = Path(__file__).resolve().parents[1]
SIZES = {"rows": 6, "sockets": 2, "touches": 3}  # small: readings or placements


def _length(truth: dict, values) -> np.ndarray:
    scale = {"mm": 1e-3, "m": 1.0}[truth["units"]["length"]]
    return np.asarray(values, float) * scale


def _angle(truth: dict, values) -> np.ndarray:
    scale = {"deg": np.pi / 180, "rad": 1.0}[truth["units"]["angle"]]
    return np.asarray(values, float) * scale


# The truth file's mounted and placement values in each model's unknowns (SI), read here
# independently of the models: (mounted vector, placement vector).

def _tracker_truth(truth, model):
    T_world_instrument = pose_from_xyz_rpy(_length(truth, truth["placement"]["instrument"]["xyz"]),
                                           _angle(truth, truth["placement"]["instrument"]["rpy"]))
    T = invert(T_world_instrument)
    model = model.with_reference(T[:3, :3])  # the instrument frame's rotation, angles zero
    return (_length(truth, truth["mounted"]["target"]),
            np.concatenate([T[:3, 3], np.zeros(3)]), model)


def _touch_truth(truth, model):
    sockets = truth["placement"]["sockets"]
    placement = np.zeros(len(model.placement))
    for name in model.placement.names:  # <label>/pose<k>/<socket>_<axis>
        pose, socket, axis = re.fullmatch(r".*/pose(\d+)/(.+)_([xyz])", name).groups()
        placement[model.placement.index(name)] = _length(
            truth, sockets[int(pose)][socket])["xyz".index(axis)]
    return _length(truth, truth["mounted"]["probe"]), placement, model


def _laser_truth(truth, model):
    mounted = np.concatenate([_length(truth, truth["mounted"]["laser_origin"]),
                              truth["mounted"]["laser_direction"]])
    return mounted, _length(truth, truth["placement"]["sphere_centre"]), model


TRUTH = {"tracker_points": _tracker_truth, "cross_bar": _touch_truth,
         "artifact_touches": _touch_truth, "sphere_laser": _laser_truth}


@pytest.fixture(scope="module", params=sorted(INSTRUMENTS))
def case(request, tmp_path_factory):
    """(model, problem, true x) for a noise-free simulation of one registered kind."""
    kind = request.param
    assert kind in TRUTH, f"no truth reader for the registered kind {kind!r}"
    rows = 16 if INSTRUMENTS[kind].model.unit_name == "readings" else 3
    sim = simulate(industrial_6r(), kind, out_dir=tmp_path_factory.mktemp(kind), rows=rows,
                   noise=0.0, geometric_errors=(5e-4, 1e-3), seed=3, progress=False,
                   sockets=SIZES["sockets"], touches=SIZES["touches"])
    dataset = sim.load()
    truth = yaml.safe_load(sim.truth_path.read_text())
    mounted, placement, model = TRUTH[kind](truth, model_for(dataset, "d"))
    problem = Problem(dataset.robot, [model])
    assert problem.models == (model,)  # a model with its reference keeps it
    x = problem.initial().copy()
    registry = dataset.robot.parameters()
    for name, value in truth["robot"].items():
        scale = {"length": _length(truth, 1.0), "angle": _angle(truth, 1.0)}.get(
            registry.quantity(name), 1.0)
        x[problem.unknowns.index(name)] = float(value) * float(scale)
    x[problem.mounted_indices(model)] = mounted
    x[problem.placement_indices(model)] = placement
    return model, problem, x


def test_every_registered_model_says_what_the_toolkit_asks():
    for kind, model in ((k, r.model) for k, r in INSTRUMENTS.items()):
        assert issubclass(model, MeasurementModel) and model.kind == kind
        assert model.reach in ("configuration", "sockets", "beam")
        assert model.table.endswith(".csv") and model.error_title and model.unit_name


def test_models_are_immutable_and_problems_leave_them_alone(case):
    """Setting up a problem places its own copies (the tracker's reference rotation)
    and leaves the models it was given as they were; no model can be changed."""
    model, problem, _ = case
    with pytest.raises(AttributeError, match="immutable"):
        model.label = "other"
    fresh = model_for(model.dataset, "fresh")
    before = {k: v for k, v in vars(fresh).items() if isinstance(v, np.ndarray)}
    placed = Problem(model.dataset.robot, [fresh]).models[0]
    for name, value in before.items():
        np.testing.assert_array_equal(getattr(fresh, name), value)
    if hasattr(fresh, "R0"):  # placed: the rotation of a registration, not the identity
        assert np.array_equal(fresh.R0, np.eye(3)) and not np.allclose(placed.R0, np.eye(3))
        assert placed is not fresh and placed.referenced and not fresh.referenced


def test_residual_vanishes_at_the_simulated_truth(case):
    model, problem, x = case
    r = problem.residual(x)
    # touches are seated by inverse kinematics to 1e-9 m; the rest is exact geometry
    assert np.max(np.abs(r)) < 1e-8, f"{model.kind}: largest residual {np.max(np.abs(r)):.3g} m"
    off = x.copy()
    off[problem.slices["robot"]] += 1e-4  # 0.1 mm and 0.1 mrad off: the data see it
    assert np.max(np.abs(problem.residual(off))) > 1e-6


def test_jacobian_matches_central_differences(case):
    model, problem, x = case
    rng = np.random.default_rng(0)
    x = x + 1e-5 * rng.normal(size=len(x))  # off the truth: no special point
    J = problem.jacobian(x)
    step = 1e-6
    numeric = np.empty_like(J)
    for j in range(len(x)):
        e = np.zeros(len(x))
        e[j] = step
        numeric[:, j] = (problem.residual(x + e) - problem.residual(x - e)) / (2 * step)
    scale = max(np.max(np.abs(J)), 1.0)
    assert np.max(np.abs(J - numeric)) < 1e-6 * scale, model.kind


def test_shapes_agree_with_the_declarations(case):
    model, problem, x = case
    r = problem.residual(x)
    assert r.shape == (model.residual_size(),)
    assert problem.jacobian(x).shape == (model.residual_size(), len(x))
    errors = model.errors(r)
    assert errors.shape == model.error_rows().shape
    assert np.all(model.errors(np.ones_like(r)) > 0)
    assert model.residual_groups().shape == (model.residual_size(),)
    assert len(model.nominal_mounted()) == len(model.mounted)
    assert len(model.nominal_placement({s: np.zeros(3) for s in
                                        getattr(model.dataset, "point", ())})) == \
        len(model.placement)
    names, chart = model.mounted_chart(model.nominal_mounted())
    assert np.allclose(np.asarray(chart(np.zeros(len(names)))).ravel(), model.nominal_mounted())
    if model.separable:  # the residual is exactly the rows' entries
        assert model.row_data().shape[0] == model.dataset.rows


def test_units_residual_in_metres_per_metre_of_placement(case):
    """Residuals and length unknowns share one SI unit: moving the instrument by 1 um
    changes the residual by about 1 um (a column of a length placement unknown has
    entries of order one), and the errors are lengths of the residual's parts."""
    model, problem, x = case
    J = problem.jacobian(x)
    columns = problem.placement_indices(model)
    for name, column in zip(model.placement.names, columns):
        if model.placement.quantity(name) == "length":
            assert 0.5 < np.max(np.abs(J[:, column])) <= 1.0 + 1e-9, name
    r = problem.residual(x) + 1e-6
    assert np.all(model.errors(r) < 2e-6)


def test_kind_strings_live_only_in_the_instrument_packages():
    """Only the instrument packages spell a dataset kind (each its own, in its
    ``Instrument`` record and docstrings); the reader, planner, simulator, report and
    commands ask the registry."""
    spelled = re.compile("|".join(sorted(INSTRUMENTS)))
    home = ROOT / "robocal_casadi" / "instruments"
    found = []
    for folder in (ROOT / "robocal_casadi", ROOT / "planning"):
        for path in sorted(folder.rglob("*.py")):
            if home in path.parents:
                continue
            for number, line in enumerate(path.read_text().splitlines(), start=1):
                if spelled.search(line):
                    found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not found, "dataset kinds spelled outside the instrument packages:\n" + "\n".join(found)


def test_each_kind_is_spelled_only_in_its_own_package():
    """Inside ``instruments/``, a kind's name appears only in its own package and in its
    registry line (``instruments/__init__.py``); the registry and the shared modules name
    none, so a kind's folder is its one home."""
    home = ROOT / "robocal_casadi" / "instruments"
    found = []
    for path in sorted(home.rglob("*.py")):
        if path == home / "__init__.py":
            continue
        owner = path.relative_to(home).parts[0] if path.parent != home else None
        for kind, record in INSTRUMENTS.items():
            package = record.model.__module__.split(".")[2]
            if owner == package:
                continue
            for number, line in enumerate(path.read_text().splitlines(), start=1):
                if kind in line:
                    found.append(f"{path.relative_to(ROOT)}:{number}: {kind}")
    assert not found, "kinds spelled outside their own package:\n" + "\n".join(found)


@pytest.mark.parametrize("kind", sorted(INSTRUMENTS))
def test_planner_rows_are_the_engine_jacobian_of_the_planned_data(kind, tmp_path):
    """The planner's Jacobian rows of a candidate are the engine's Jacobian of the
    dataset made of that candidate, at the nominal robot and instrument: the mounted
    columns through the model's chart (the beam in its tangent plane), local placement
    unknowns projected out, shared ones kept."""
    from planning.candidates import generate
    from planning.planned import planned_dataset
    from planning.reach import Workspace
    from planning.rows import RowModel
    from planning.setup import setup_from_dataset
    from robocal_casadi.instruments.datasets import load_dataset
    from robocal_casadi.model.kinematics import Kinematics

    sim = simulate(industrial_6r(), kind, out_dir=tmp_path / kind, rows=2, seed=1,
                   progress=False, sockets=2, touches=2)
    dataset = load_dataset(sim.dataset_path, require_data=False)
    setup = setup_from_dataset(dataset)
    kinematics = Kinematics(setup.robot)
    workspace = Workspace(kinematics, table_height=setup.table_height)
    candidates = generate(setup, workspace, 10, np.random.default_rng(0))
    if not setup.model.placement_shared:
        candidates = candidates[:1]  # one placement: its sockets are the local unknowns
    block = np.vstack([b.X for b in RowModel(setup, kinematics).blocks(candidates)])

    model = model_for(planned_dataset(dataset, candidates, kinematics), "plan")
    if hasattr(model, "with_reference"):
        model = model.with_reference(np.eye(3))  # the planner's frame is the world frame
    problem = Problem(dataset.robot, [model])
    x = problem.initial().copy()
    x[problem.slices["robot"]] = kinematics.nominal
    x[problem.mounted_indices(model)] = model.nominal_mounted()
    x[problem.placement_indices(model)] = model.nominal_placement(candidates[0].sockets)
    J = problem.jacobian(x)
    nominal = model.nominal_mounted()
    names, chart = model.mounted_chart(nominal)
    chart_jacobian = np.column_stack([  # d mounted / d chart coordinates (chart is affine)
        np.asarray(chart(np.eye(len(names))[:, k])).ravel() - nominal
        for k in range(len(names))])
    G = np.hstack([J[:, problem.slices["robot"]],
                   J[:, problem.mounted_indices(model)] @ chart_jacobian])
    S = J[:, problem.placement_indices(model)]
    if model.placement_shared:
        engine = np.hstack([G, S])
    else:
        U, s, _ = np.linalg.svd(S, full_matrices=False) if S.shape[1] else (
            np.zeros((len(G), 0)), np.zeros(0), None)
        U = U[:, s > 1e-12 * max(s.max(initial=0.0), 1e-300)]
        engine = G - U @ (U.T @ G)
    engine = engine[np.abs(engine).sum(axis=1) > 0]  # the laser's gauge row has no chart part
    assert engine.shape == block.shape
    assert np.allclose(engine.T @ engine, block.T @ block, rtol=1e-9,
                       atol=1e-9 * np.max(np.abs(block.T @ block)))
