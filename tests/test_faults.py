"""Faults a careful user meets: repeated readings, API arguments of the wrong kind,
Ctrl-C, counts beyond reason, an unreachable scheduler, odd file names and units, and a
structured residual that must stay within the fit it is part of.

Data come from the shipped UR10 tracker series and from ``robocal_casadi.simulate``.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from robocal_casadi import calibrate, compensate, load_dataset, load_robot
from robocal_casadi.cli import MAX_MESSAGE, main
from robocal_casadi.errors import ArgumentError, InputError, SolverError
from robocal_casadi.instruments.simulate import MAX_ROWS, simulate
from robocal_casadi.model.examples import ROBOTS

REPOSITORY = Path(__file__).resolve().parents[1]
UR10 = REPOSITORY / "robocal_casadi" / "data" / "ur10-ipa"
STAGING = re.compile(r"\..+\.robocal-\d+-.*")  # output.py's staging names


@pytest.fixture()
def ur10(tmp_path) -> Path:
    """A copy of the UR10 fit series (tracker, mm/rad) to edit; returns its folder."""
    folder = tmp_path / "ur10"
    folder.mkdir()
    for name in ("robot.yaml", "series_D_fit.yaml", "series_D_fit.csv"):
        shutil.copy(UR10 / name, folder / name)
    return folder


def _dataset_with_rows(folder: Path, name: str, header: str, rows: list[str],
                       **replace: str) -> Path:
    """A copy of the UR10 dataset file named ``name`` whose table holds ``rows``."""
    (folder / f"{name}.csv").write_text("\n".join([header] + rows) + "\n")
    text = (folder / "series_D_fit.yaml").read_text().replace("series_D_fit.csv", f"{name}.csv")
    for old, new in replace.items():
        text = text.replace(old, new)
    (folder / f"{name}.yaml").write_text(text)
    return folder / f"{name}.yaml"


def _one_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


# ----------------------------------------------------------------------------- repeats


def test_repeated_tracker_readings_are_judged_as_the_distinct_ones(ur10):
    header, *rows = (ur10 / "series_D_fit.csv").read_text().splitlines()
    distinct = _dataset_with_rows(ur10, "two", header, rows[:2])
    repeated = _dataset_with_rows(ur10, "repeated", header, rows[:2] * 40)
    with pytest.raises(InputError) as plain:
        calibrate([load_dataset(distinct)], diagnose=False)
    with pytest.raises(InputError) as copies:
        calibrate([load_dataset(repeated)], diagnose=False)
    assert "cannot identify" in str(plain.value)
    assert "cannot identify" in str(copies.value) and "78 of 80" in str(copies.value)


def test_one_bar_placement_copied_twelve_times_is_refused(tmp_path):
    sim = simulate(ROBOTS["industrial_6r"](), "cross_bar", rows=2, seed=3, noise=1e-5,
                   out_dir=tmp_path / "bar", progress=False)
    header, *rows = sim.table_path.read_text().splitlines()
    first = [r for r in rows if r.startswith("0,")]
    copied = [f"{k}{r[1:]}" for k in range(12) for r in first]
    sim.table_path.write_text("\n".join([header] + copied) + "\n")
    with pytest.raises(InputError) as refused:
        calibrate([load_dataset(sim.dataset_path)], diagnose=False)
    assert "distinct readings" in str(refused.value) and "11 of 12" in str(refused.value)


# ----------------------------------------------------------------------------- API


def test_unknown_parameter_names_are_refused_with_a_hint():
    dataset = load_dataset(UR10 / "series_D_fit.yaml")
    with pytest.raises(ArgumentError, match="'bogus9'") as unknown:
        calibrate([dataset], parameters=["a2", "bogus9"])
    assert unknown.value.argument == "parameters"
    with pytest.raises(ArgumentError, match="did you mean 'alpha2'"):
        calibrate([dataset], parameters=["alph2"])
    with pytest.raises(ArgumentError, match="text"):
        calibrate([dataset], parameters=["a2", 3])
    with pytest.raises(ArgumentError, match="a name or a list|list of names"):
        calibrate([dataset], parameters=7)


def test_a_single_parameter_name_is_one_name():
    result = calibrate([load_dataset(UR10 / "series_D_fit.yaml")], parameters="a2",
                       diagnose=False)
    robot_names = set(load_robot(UR10 / "robot.yaml").parameters().names)
    fitted = {p.name for p in result.parameters if p.identifiable and p.name in robot_names}
    assert fitted == {"a2"}


def test_paths_and_wrong_types_at_the_api_door(tmp_path):
    with pytest.raises(ArgumentError, match="path") as none:
        load_dataset(None)
    assert "None" in str(none.value)
    with pytest.raises(ArgumentError):
        load_dataset(UR10 / "series_D_fit.yaml", robot=42)
    by_path = load_dataset(UR10 / "series_D_fit.yaml", robot=str(UR10 / "robot.yaml"))
    by_file = load_dataset(UR10 / "series_D_fit.yaml")
    assert by_path.robot == by_file.robot and np.array_equal(by_path.joints, by_file.joints)
    with pytest.raises(ArgumentError, match="robot"):
        compensate(None, [[0.5, 0.2, 0.4]])
    for bad in ([[np.nan, 0.2, 0.4]], [[0.5, np.inf, 0.4]], "abc", [[0.5, 0.2]],
                [[0.5, 0.2, 0.4, 0, 0, 0, 0]]):
        with pytest.raises(ArgumentError) as refused:
            compensate(UR10 / "robot.yaml", bad)
        assert refused.value.argument == "targets"


def test_compensate_takes_a_robot_file(tmp_path):
    robot = load_robot(UR10 / "robot.yaml")
    from robocal_casadi.model.kinematics import Kinematics

    q = np.array([0.3, -1.2, 1.0, -0.5, 1.1, 0.2])
    point = Kinematics(robot).tool_poses(q[None])[0, :3, 3] * 1000.0  # the file's mm
    by_file = compensate(str(UR10 / "robot.yaml"), [point])
    by_robot = compensate(robot, [point])
    assert by_file.status == by_robot.status == ("ok",)
    assert np.allclose(by_file.joints, by_robot.joints)


# ----------------------------------------------------------------------------- signals


INTERRUPTING = textwrap.dedent("""
    import os, signal, sys, threading
    from robocal_casadi.cli import main
    delay = float(sys.argv[1])
    threading.Timer(delay, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
    sys.exit(main(sys.argv[2:]))
""")


@pytest.mark.parametrize("delay", [0.5, 1.5])
def test_ctrl_c_is_one_line_exit_130_and_writes_nothing(tmp_path, delay):
    """SIGINT while the shipped UR10 series is calibrated and validated: while the
    libraries load, and later (the whole run takes about 5.6 s on a 2-core machine: a
    delay near it would let a faster machine finish first)."""
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-c", INTERRUPTING, str(delay), "calibrate",
                          str(UR10 / "series_D_fit.yaml"), "--validate",
                          str(UR10 / "series_D_validation.yaml"), "--out", str(out)],
                         capture_output=True, text=True, timeout=600, cwd=REPOSITORY)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 130, run.stderr[-2000:]
    assert lines[-1] == "robocal calibrate: interrupted; no output was left half-written"
    assert "Traceback" not in run.stderr
    assert not out.exists() and not [p for p in tmp_path.iterdir() if "robocal" in p.name]


def test_the_command_loads_nothing_slow_before_its_handler():
    """``import robocal_casadi.cli`` (what the ``robocal`` script does before ``main``)
    loads none of the numerical libraries, so Ctrl-C meets the command's handler early."""
    run = subprocess.run([sys.executable, "-c", "import sys, robocal_casadi.cli; print(sorted("
                          "m for m in ('numpy', 'scipy', 'casadi', 'pinocchio', 'yaml') "
                          "if m in sys.modules))"], capture_output=True, text=True, timeout=120,
                         cwd=REPOSITORY)
    assert run.returncode == 0 and run.stdout.strip() == "[]", run.stdout + run.stderr


EARLY = textwrap.dedent("""
    import os, signal, sys
    sys.argv[0] = "/usr/local/bin/robocal"  # as the installed script
    from robocal_casadi.cli import main
    os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C before main has run
    sys.exit(main(sys.argv[1:]))
""")


def test_ctrl_c_before_main_runs_is_one_line_in_the_verbs_name(tmp_path):
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-c", EARLY, "calibrate",
                          str(UR10 / "series_D_fit.yaml"), "--out", str(out)],
                         capture_output=True, text=True, timeout=300, cwd=REPOSITORY)
    assert run.returncode == 130, run.stderr[-2000:]
    assert run.stderr.strip().splitlines() == [
        "robocal calibrate: interrupted; no output was left half-written"], run.stderr[-2000:]
    assert not out.exists()


def test_ctrl_c_while_the_verbs_are_loaded_names_the_verb(monkeypatch, capsys, tmp_path):
    """Under load, the verbs' modules may still be importing when Ctrl-C comes: the line
    names the verb all the same (read from the command line before anything slow)."""
    from robocal_casadi import cli

    def loading(*args, **kwargs):
        raise KeyboardInterrupt  # as the handler raises it in the middle of an import

    monkeypatch.setattr(cli, "build_parser", loading)
    status = main(["--quiet", "simulate", "--example", "ur_type", "--out", str(tmp_path / "o")])
    assert status == 130
    assert _one_line(capsys) == "robocal simulate: interrupted; no output was left half-written"
    assert not (tmp_path / "o").exists()


def test_an_interruption_a_library_swallowed_still_stops_the_output(tmp_path, monkeypatch,
                                                                     capsys):
    """The handler notes the interruption; a run that carries on writes nothing."""
    from robocal_casadi.commands import simulate as simulate_verb
    from robocal_casadi.common.output import atomic_directory, note_interrupt

    def carries_on(args) -> int:
        note_interrupt()  # as the handler does before a solver catches the exception
        with atomic_directory(tmp_path / "out") as staging:
            (staging / "result.json").write_text("{}")
        return 0

    monkeypatch.setattr(simulate_verb, "run", carries_on)
    status = main(["simulate", "--example", "ur_type", "--kind", "tracker_points", "--out",
                   str(tmp_path / "out")])
    assert status == 130 and "interrupted" in _one_line(capsys)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    capsys.readouterr()
    assert main(["simulate", "--example", "ur_type", "--kind", "tracker_points", "--rows", "4",
                 "--out", str(tmp_path / "later")]) == 0  # the next run starts afresh


def test_ctrl_c_to_a_fleet_reaches_no_worker(ur10, tmp_path):
    """Ctrl-C goes to the terminal's whole process group: the fleet's worker processes
    get it too and must print nothing; the verb ends as any other."""
    pytest.importorskip("dask.distributed")
    (ur10 / "fleet.yaml").write_text("robots:\n  - name: a\n    datasets: [series_D_fit.yaml]\n"
                                     "  - name: b\n    datasets: [series_D_fit.yaml]\n")
    out = tmp_path / "fleet-out"
    process = subprocess.Popen([sys.executable, "-m", "robocal_casadi.cli", "fleet",
                                str(ur10 / "fleet.yaml"), "--out", str(out), "--workers", "1",
                                "--no-report"], cwd=REPOSITORY, start_new_session=True,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        process.wait(timeout=4.0)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGINT)
    _, err = process.communicate(timeout=300)
    assert process.returncode == 130, err[-2000:]
    assert err.strip().splitlines() == [
        "robocal fleet: interrupted; no output was left half-written"], err[-2000:]
    if out.exists():  # robots finished before the interruption are kept whole
        staging = [p.name for p in out.rglob("*") if STAGING.fullmatch(p.name)]
        assert staging == [] and not (out / "fleet.json").exists()


@pytest.mark.parametrize("raised", [SolverError("the solver was stopped"),
                                    SystemError("returned a result with an exception set")])
def test_an_interruption_a_library_turned_into_its_error_is_one_line(monkeypatch, capsys,
                                                                     raised):
    """A solver that catches Ctrl-C and raises its own error: still 'interrupted'."""
    from robocal_casadi.commands import simulate as simulate_verb
    from robocal_casadi.common.output import note_interrupt

    def stopped(args) -> int:
        note_interrupt()
        raise raised

    monkeypatch.setattr(simulate_verb, "run", stopped)
    status = main(["simulate", "--example", "ur_type", "--kind", "tracker_points", "--out",
                   "unused"])
    assert status == 130 and _one_line(capsys).endswith("interrupted; no output was left "
                                                        "half-written")


# ----------------------------------------------------------------------------- counts


@pytest.mark.parametrize("options, option", [
    (["--kind", "tracker_points", "--rows", "10000000000"], "--rows"),
    (["--kind", "cross_bar", "--rows", str(MAX_ROWS // 4 + 1)], "--rows"),
    (["--kind", "artifact_touches", "--rows", "10", "--touches", "10000000000"], "--touches"),
])
def test_simulated_counts_are_bounded(tmp_path, capsys, options, option):
    status = main(["simulate", "--example", "ur_type", *options, "--out", str(tmp_path / "s")])
    line = _one_line(capsys)
    assert status == 2 and option in line and f"{MAX_ROWS:,}" in line
    assert not (tmp_path / "s").exists()
    with pytest.raises(ArgumentError, match="rows"):
        simulate(ROBOTS["ur_type"](), "tracker_points", rows=10**10, out_dir=tmp_path / "s")


# ----------------------------------------------------------------------------- fleet


@pytest.mark.parametrize("address", ["garbage address!!", "tcp://host:99999", "http://x:1",
                                     "tcp://127.0.0.1:9"])
def test_an_unreachable_scheduler_leaves_no_folder(ur10, tmp_path, capsys, address):
    pytest.importorskip("dask.distributed")
    (ur10 / "fleet.yaml").write_text("robots:\n  - name: a\n    datasets: [series_D_fit.yaml]\n")
    out = tmp_path / "fleet-out"
    status = main(["fleet", str(ur10 / "fleet.yaml"), "--out", str(out), "--scheduler",
                   address, "--no-report"])
    line = _one_line(capsys)
    assert status == 2 and "--scheduler" in line
    assert not out.exists()


# ----------------------------------------------------------------------------- files


def test_a_huge_file_name_is_one_short_line_naming_file_and_key(ur10, capsys):
    text = (ur10 / "series_D_fit.yaml").read_text().replace("series_D_fit.csv", "x" * 3_000_000)
    (ur10 / "long.yaml").write_text(text)
    with pytest.raises(InputError) as refused:
        load_dataset(ur10 / "long.yaml")
    assert refused.value.where == "data" and len(str(refused.value)) < 400
    assert main(["calibrate", str(ur10 / "long.yaml"), "--out", str(ur10 / "o")]) == 2
    line = _one_line(capsys)
    assert "long.yaml" in line and "data" in line and len(line) <= MAX_MESSAGE + 40


@pytest.mark.parametrize("special", ["fifo", "/dev/zero"])
def test_a_robot_that_is_no_regular_file_is_named_so(ur10, special):
    if special == "fifo":
        os.mkfifo(ur10 / "pipe.yaml")
        special = "pipe.yaml"
    text = (ur10 / "series_D_fit.yaml").read_text().replace("robot.yaml", special)
    (ur10 / "odd.yaml").write_text(text)
    with pytest.raises(InputError, match="not a regular file") as refused:
        load_dataset(ur10 / "odd.yaml")
    assert refused.value.where == "robot" and "not found" not in str(refused.value)


def test_empty_trailing_header_cells_are_accepted(ur10):
    header, *rows = (ur10 / "series_D_fit.csv").read_text().splitlines()
    trailing = _dataset_with_rows(ur10, "trailing", header + ",,", [r + ",," for r in rows])
    clean = load_dataset(ur10 / "series_D_fit.yaml")
    read = load_dataset(trailing)
    assert np.array_equal(read.joints, clean.joints)
    assert np.array_equal(read.measured, clean.measured)
    filled = _dataset_with_rows(ur10, "filled", header + ",,", [r + ",,1" for r in rows])
    with pytest.raises(InputError, match="no name"):
        load_dataset(filled)


def test_radians_in_a_file_that_declares_degrees_get_a_units_hint(ur10):
    header, *rows = (ur10 / "series_D_fit.csv").read_text().splitlines()
    wrong = _dataset_with_rows(ur10, "deg", header, rows, **{"angle: rad": "angle: deg"})
    with pytest.raises(InputError, match="radians in a file that declares deg"):
        load_dataset(wrong)


# ----------------------------------------------------------------------------- unexplained


def test_unexplained_residual_never_exceeds_the_fit_it_is_part_of(tmp_path):
    """Twelve bar placements, noise only: whatever is reported as structure is a share of
    the fit's own RMS (before, held-out extrapolation reported 2,000 times the fit)."""
    sim = simulate(ROBOTS["industrial_6r"](), "cross_bar", rows=12, noise=1e-5,
                   geometric_errors=(5e-4, 5e-4), seed=1, out_dir=tmp_path / "bar",
                   progress=False)
    result = calibrate([load_dataset(sim.dataset_path)], diagnose=False)
    found = result.unexplained
    assert found is None or found.rms <= result.fit.rms_final * (1 + 1e-12)
