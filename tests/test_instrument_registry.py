"""Adding a kind touches its own module and one registry line.

``string_gauge_instrument`` is a kind the package does not know: a draw-wire gauge from a
fixed anchor to the flange, written in one module that registers itself. Once imported,
the toolkit reads, simulates and calibrates its data with nothing changed anywhere else;
the checks here compare what it estimates with the simulated truth.
"""

from __future__ import annotations

import importlib
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal_casadi.calibration import calibrate
from robocal_casadi.errors import InputError
from robocal_casadi.instruments import INSTRUMENTS, Instrument, instrument, kinds, register
from robocal_casadi.instruments.datasets import dataset_rows, load_dataset
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import industrial_6r
from robocal_casadi.model.kinematics import Kinematics

ROOT = Path(__file__).resolve().parents[1]
MODULE = "string_gauge_instrument"


@pytest.fixture(scope="module")
def gauge():
    """The test kind's module, registered for this module's tests and removed after (the
    other tests see only the built-in kinds)."""
    sys.path.insert(0, str(Path(__file__).parent))
    try:
        module = importlib.import_module(MODULE)
        yield module
    finally:
        sys.path.remove(str(Path(__file__).parent))
        INSTRUMENTS.pop("string_gauge", None)
        sys.modules.pop(MODULE, None)


def test_the_kind_is_registered_by_its_one_line(gauge):
    assert instrument(gauge.KIND) is gauge.INSTRUMENT
    assert kinds()[-1] == gauge.KIND
    source = Path(gauge.__file__).read_text()
    assert source.count("register(") == 1  # the one registry line


def test_nothing_outside_the_kinds_module_names_it(gauge):
    for folder in (ROOT / "robocal_casadi", ROOT / "planning"):
        for path in folder.rglob("*.py"):
            assert gauge.KIND not in path.read_text(), path


def test_a_kind_is_registered_once(gauge):
    with pytest.raises(ValueError, match="registered already"):
        register(gauge.INSTRUMENT)


def test_a_record_must_name_its_models_kind(gauge):
    record = Instrument(kind="other_gauge", model=gauge.StringGaugeModel,
                        blocks={}, read=gauge.read)
    with pytest.raises(ValueError, match="models kind"):
        register(record)
    assert "other_gauge" not in INSTRUMENTS


@pytest.fixture(scope="module")
def simulated(gauge, tmp_path_factory):
    return simulate(industrial_6r(), gauge.KIND, out_dir=tmp_path_factory.mktemp("gauge"),
                    rows=60, noise=0.0, geometric_errors=(3e-4, 5e-4), seed=5, progress=False)


def test_simulate_writes_and_read_loads_the_new_kind(gauge, simulated):
    dataset = load_dataset(simulated.dataset_path)
    assert isinstance(dataset, gauge.StringGauge) and dataset.kind == gauge.KIND
    assert simulated.table_path.name == gauge.StringGaugeModel.table
    truth = yaml.safe_load(simulated.truth_path.read_text())
    scale = dataset.units.length_scale
    true_hook = np.asarray(truth["mounted"]["hook"], float) * scale
    true_anchor = np.asarray(truth["placement"]["anchor"], float) * scale
    # the wire lengths, recomputed here from the true robot's flange poses
    poses = Kinematics(simulated.truth.robot).flange_poses(dataset.joints)  # no effects
    expected = np.linalg.norm(poses[:, :3, :3] @ true_hook + poses[:, :3, 3] - true_anchor,
                              axis=1)
    # the table holds the lengths in the file's unit with about 16 significant digits
    np.testing.assert_allclose(dataset.length, expected, rtol=0, atol=1e-12)
    half = dataset_rows(dataset, np.arange(dataset.rows) < 30)
    np.testing.assert_array_equal(half.length, dataset.length[:30])


def test_the_new_kind_calibrates_to_its_simulated_truth(gauge, simulated):
    dataset = load_dataset(simulated.dataset_path)
    result = calibrate([dataset], diagnose=False, loss="linear")
    before = result.fit.rms_nominal
    after = result.fit.rms_final
    assert before > 1e-4  # the geometric errors lengthen the wire by a tenth of a mm or more
    # noise-free readings: what is left is the solver's tolerance, far below the errors
    assert after < 1e-3 * before


def test_bad_keys_of_the_new_kind_are_refused(gauge, simulated, tmp_path):
    content = yaml.safe_load(simulated.dataset_path.read_text())
    content["hook"]["xzy"] = [0, 0, 0]
    for name in ("robot.yaml", simulated.table_path.name):
        (tmp_path / name).write_bytes((simulated.dataset_path.parent / name).read_bytes())
    path = tmp_path / "dataset.yaml"
    path.write_text(yaml.safe_dump(content))
    with pytest.raises(InputError, match="xzy"):
        load_dataset(path)


def test_planning_a_kind_without_a_planner_is_refused(gauge, simulated):
    """The gauge brings no planner: ``plan`` says so, naming the dataset file and key."""
    from planning.setup import setup_from_dataset

    dataset = load_dataset(simulated.dataset_path, require_data=False)
    with pytest.raises(InputError, match="no set-up for string_gauge") as caught:
        setup_from_dataset(dataset)
    assert Path(caught.value.file).name == "dataset.yaml" and caught.value.where == "kind"


def test_path_effects_are_simulated_where_the_registry_says_readings_are_taken_anywhere(
        gauge, tmp_path):
    """Whether an effect needing absolute points along a path (``tracker_only``) can be
    simulated is the kind's record's say (``any_configuration``), not its model's: the gauge
    does not declare it and is refused; the same record declaring it is simulated."""
    record = INSTRUMENTS[gauge.KIND]
    assert not record.any_configuration and instrument("tracker_points").any_configuration
    with pytest.raises(InputError, match="any configuration .* not for string_gauge"):
        simulate(industrial_6r(), gauge.KIND, out_dir=tmp_path / "refused", rows=4,
                 effects={"hysteresis": {2: 1e-3}}, progress=False)
    INSTRUMENTS[gauge.KIND] = replace(record, any_configuration=True)
    try:
        run = simulate(industrial_6r(), gauge.KIND, out_dir=tmp_path / "taken", rows=4,
                       effects={"hysteresis": {2: 1e-3}}, progress=False)
    finally:
        INSTRUMENTS[gauge.KIND] = record
    assert run.truth.effects.names == ("hysteresis",)
