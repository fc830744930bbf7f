"""Options every verb shares (--version, --quiet, --json), refusals in the verb's name,
one file per --validate, one way to name a calibration, and fleet's calibrate options."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from robocal_casadi import __version__
from robocal_casadi.cli import VERBS, build_parser, main
from robocal_casadi.common.table import read_table

SIMULATE = ["simulate", "--example", "industrial_6r", "--kind", "tracker_points", "--rows", "40",
            "--noise", "0.01", "--error", "a2=0.3", "--error", "theta3=0.05"]


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    """A simulated tracker dataset and a calibration of it (fit/, val/, result/)."""
    root = tmp_path_factory.mktemp("cli")
    assert main([*SIMULATE, "--seed", "1", "--out", str(root / "fit")]) == 0
    assert main([*SIMULATE, "--seed", "2", "--out", str(root / "val")]) == 0
    assert main(["calibrate", str(root / "fit" / "dataset.yaml"), "--out", str(root / "result"),
                 "--no-diagnose", "--no-report"]) == 0
    lines = ["x,y,z"] + [f"{900 + 10 * k},{50 * k},{700 - 20 * k}" for k in range(4)]
    (root / "targets.csv").write_text("\n".join(lines) + "\n")
    return root


def test_version(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == f"robocal {__version__}"


@pytest.mark.parametrize("verb", VERBS)
def test_an_unknown_option_is_refused_in_the_verbs_name(verb, capsys):
    needed = {"calibrate": ["d.yaml", "--out", "o"], "plan": ["d.yaml", "--count", "3",
                                                             "--out", "p.csv"],
              "track": ["j.yaml", "--out", "o.csv"], "fk": ["r.yaml", "j.csv", "--out", "o.csv"],
              "simulate": ["--example", "industrial_6r", "--kind", "cross_bar", "--out", "o"],
              "compensate": ["r.yaml", "t.csv", "--out", "o.csv"], "export": ["d"],
              "demo": [], "fleet": ["f.yaml", "--out", "o"],
              "prior": ["r1", "--out", "p.yaml"]}[verb]
    with pytest.raises(SystemExit) as stop:
        main([verb, *needed, "--no-such-option", "7"])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith(f"robocal {verb}: error: unrecognized arguments: --no-such-option")


def test_top_level_help_gives_every_verb_a_whole_sentence(capsys):
    """``robocal --help`` lists each verb with its summary, never cut mid-sentence."""
    import importlib

    with pytest.raises(SystemExit):
        main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    for verb in VERBS:
        doc = importlib.import_module(f"robocal_casadi.commands.{verb}").__doc__
        first = " ".join(doc.strip().split("\n\n")[0].split())
        assert first.endswith("."), f"{verb}: {first!r} is not a whole sentence"
        assert f" {verb} {first} " in f"{text} ", verb


@pytest.mark.parametrize("verb", VERBS)
def test_every_verb_takes_quiet_and_json(verb):
    parser = build_parser()
    actions = {a.dest for a in parser._subparsers._group_actions[0].choices[verb]._actions}
    assert {"quiet", "json"} <= actions


def test_validate_takes_one_file(data, tmp_path, capsys):
    """The file after --validate's one file is a dataset to fit, not swallowed."""
    out = tmp_path / "r"
    code = main(["calibrate", "--validate", str(data / "val" / "dataset.yaml"),
                 str(data / "fit" / "dataset.yaml"), "--out", str(out), "--no-diagnose",
                 "--no-report", "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["validation_rms"] is not None and len(summary["datasets"]) == 1
    result = json.loads((out / "result.json").read_text())
    assert result["validation"] is not None


def test_no_diagnose_says_diagnosis_was_not_run(data, tmp_path, capsys):
    code = main(["calibrate", str(data / "fit" / "dataset.yaml"), "--out", str(tmp_path / "r"),
                 "--no-diagnose", "--no-report"])
    assert code == 0
    out = capsys.readouterr().out
    assert "effects: none added" not in out
    assert "diagnosis: not run" in out
    assert "consistent with noise" not in out  # nothing was tested


def test_quiet_prints_nothing_but_an_error(data, tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["calibrate", str(data / "fit" / "dataset.yaml"), "--out", str(out),
                 "--no-report", "--quiet"]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    assert (out / "result.json").is_file()
    assert main(["calibrate", str(tmp_path / "missing.yaml"), "--out", str(tmp_path / "s"),
                 "--quiet"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "missing.yaml" in lines[0]


def _json(capsys) -> dict:
    text = capsys.readouterr().out
    assert text.count("\n") == 1, text
    return json.loads(text)


def test_json_is_the_only_thing_on_stdout(data, tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["calibrate", str(data / "fit" / "dataset.yaml"), "--validate",
                 str(data / "val" / "dataset.yaml"), "--out", str(out), "--no-report",
                 "--json"]) == 0
    summary = _json(capsys)
    result = json.loads((out / "result.json").read_text())
    assert summary["verb"] == "calibrate" and summary["exit_status"] == 0
    assert summary["unit"] == result["fit"]["unit"] == "mm"
    assert summary["condition_number"] == pytest.approx(result["condition_number"], rel=1e-12)
    assert summary["fit_rms"]["final"] == pytest.approx(result["fit"]["rms_final"], rel=1e-12)
    assert summary["identifiable"] == len(result["identifiability"]["identifiable"])
    assert "result.json" in summary["written"] and summary["diagnosed"] is True
    assert main(["calibrate", str(tmp_path / "missing.yaml"), "--out", str(tmp_path / "s"),
                 "--json"]) == 2
    refused = json.loads(capsys.readouterr().out)
    assert refused["exit_status"] == 2 and "missing.yaml" in refused["error"]


def test_json_of_the_table_verbs(data, tmp_path, capsys):
    robot = data / "fit" / "robot.yaml"
    joints = tmp_path / "joints.csv"
    assert main(["compensate", str(robot), str(data / "targets.csv"), "--calibrated",
                 str(data / "result"), "--out", str(joints), "--json"]) == 0
    summary = _json(capsys)
    assert summary["rows"] == 4 and summary["calibrated"] == str(data / "result")
    assert summary["unreachable"] == sum(s != "ok" for s in read_table(joints).text("status"))
    poses = tmp_path / "poses.csv"
    table = read_table(joints)
    (tmp_path / "q.csv").write_text(
        "\n".join([",".join(f"q{i}" for i in range(1, 7))] + [
            ",".join(table.text(f"q{i}")[k] for i in range(1, 7)) for k in range(4)]) + "\n")
    assert main(["fk", str(robot), str(tmp_path / "q.csv"), "--calibrated",
                 str(data / "result"), "--out", str(poses), "--json"]) == 0
    assert _json(capsys)["rows"] == 4


def test_compensate_names_the_calibration_as_fk_and_track_do(data, tmp_path, capsys):
    """--calibrated DIR after the robot file gives what the earlier spelling (the folder in
    the robot's place) gives; both at once is refused."""
    robot = data / "fit" / "robot.yaml"
    new, old = tmp_path / "new.csv", tmp_path / "old.csv"
    assert main(["compensate", str(robot), str(data / "targets.csv"), "--calibrated",
                 str(data / "result"), "--out", str(new)]) == 0
    assert main(["compensate", str(data / "result"), str(data / "targets.csv"), "--out",
                 str(old)]) == 0
    assert new.read_text() == old.read_text()
    plain = tmp_path / "plain.csv"
    assert main(["compensate", str(robot), str(data / "targets.csv"), "--out", str(plain)]) == 0
    assert plain.read_text() != new.read_text()  # the calibration was used
    capsys.readouterr()
    assert main(["compensate", str(data / "result"), str(data / "targets.csv"), "--calibrated",
                 str(data / "result"), "--out", str(tmp_path / "both.csv")]) == 2
    assert "--calibrated" in capsys.readouterr().err


def test_fleet_takes_calibrates_options():
    from robocal_casadi.commands.fleet import _settings

    parser = build_parser()
    args = parser.parse_args(["fleet", "f.yaml", "--out", "o", "--rule", "fraction",
                              "--profile", "dh-only", "--pdf", "--customer", "ACME",
                              "--operator", "J. Doe"])
    settings = _settings(args)
    assert settings.rule == "fraction" and settings.profile == "dh-only" and settings.pdf
    assert dict(settings.report_fields) == {"customer": "ACME", "operator": "J. Doe"}


def test_fleet_robot_gets_the_rule_profile_and_report_fields(data, tmp_path):
    """One robot's task (as a worker runs it) with the options fleet passes on."""
    from robocal_casadi.fleet import Settings, calibrate_robot
    from robocal_casadi.fleet.spec import FleetRobot

    robot = FleetRobot(name="r1", datasets=(data / "fit" / "dataset.yaml",),
                       validate=(data / "val" / "dataset.yaml",))
    settings = Settings(diagnose=False, rule="fraction", profile="dh-only",
                        report_fields=(("customer", "ACME Robotics"),),
                        allow_outside_data=True)
    outcome = calibrate_robot(robot, tmp_path, settings)
    assert outcome.status == "calibrated", outcome.error
    result = json.loads((tmp_path / "r1" / "result.json").read_text())
    assert result["prior"]["rule"] == "fraction"
    assert "profile" in result  # the dh-only restriction and what it costs
    assert "ACME Robotics" in (tmp_path / "r1" / "report.html").read_text()
    changed = Settings(diagnose=False, rule="prior", profile="dh-only",
                       report_fields=(("customer", "ACME Robotics"),), allow_outside_data=True)
    assert calibrate_robot(robot, tmp_path, changed).status == "calibrated"  # not "unchanged"


def test_fleet_without_dask_says_how_to_install_it(data, tmp_path, capsys, monkeypatch):
    """The core install has no Dask: one line naming the extra, nothing written."""
    import sys

    monkeypatch.setitem(sys.modules, "dask.distributed", None)  # import raises ImportError
    fleet = tmp_path / "fleet.yaml"
    fleet.write_text(f"robots:\n  - name: r1\n    datasets: [{data / 'fit' / 'dataset.yaml'}]\n")
    out = tmp_path / "fleet-out"
    assert main(["fleet", str(fleet), "--out", str(out), "--allow-outside-data"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pip install" in err[0] and "robocal fleet: error" in err[0]
    assert not out.exists()


def test_json_of_a_refused_command_line(capsys):
    """A command line the parser refuses still gives its JSON object under --json."""
    with pytest.raises(SystemExit) as stop:
        main(["calibrate", "d.yaml", "--out", "o", "--json", "--no-such-option"])
    assert stop.value.code == 2
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert summary["verb"] == "calibrate" and summary["exit_status"] == 2
    assert "--no-such-option" in summary["error"]
    assert captured.err.startswith("robocal calibrate: error: unrecognized arguments")
