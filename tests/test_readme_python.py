"""The README's Python session runs as written, in the worked example's folder, and uses
every function of the front door.

The folder is made by the worked example's own ``robocal simulate`` commands (as the
README says to run them first) and a tracking job written the way
docs/formats.md#tracking-job describes; the session's results are then checked against
what they must be independently of how they were computed: the compensated joints put
the calibrated tool on the poses forward kinematics gave, and the calibration written by
the session is the one ``robocal calibrate`` writes for the same files.
"""

from __future__ import annotations

import ast
import contextlib
import io
import json
import os
from pathlib import Path

import numpy as np
import pytest
from test_readme_example import README, worked_example_commands
from test_tracking import lissajous_joints, write_job

import robocal_casadi as rc
from robocal_casadi.cli import main
from robocal_casadi.model.examples import industrial_6r

FRONT_DOOR = {"load_robot", "load_dataset", "fk", "calibrate", "plan", "track",
              "compensate"}


def session() -> str:
    """The python block of the README's "Python" section."""
    text = README.read_text().split("\n## Python\n", 1)[1].split("\n## ", 1)[0]
    return text.split("```python", 1)[1].split("```", 1)[0]


def test_the_session_calls_every_front_door_function():
    called = {node.func.attr for node in ast.walk(ast.parse(session()))
              if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
              and isinstance(node.func.value, ast.Name) and node.func.value.id == "rc"}
    assert FRONT_DOOR <= called, FRONT_DOOR - called


@pytest.fixture(scope="module")
def ran(tmp_path_factory) -> tuple[Path, dict]:
    folder = tmp_path_factory.mktemp("readme-python")
    here = os.getcwd()
    os.chdir(folder)
    try:
        for command in worked_example_commands():
            if command[0] == "simulate":
                with contextlib.redirect_stdout(io.StringIO()):
                    assert main(command) == 0
        write_job(folder, industrial_6r(), lissajous_joints("industrial_6r", 8)[:8])
        namespace: dict = {}
        with contextlib.redirect_stdout(io.StringIO()):
            exec(compile(session(), "README.md", "exec"), namespace)
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(["calibrate", "bar/dataset.yaml", "--validate",
                         "bar-check/dataset.yaml", "--out", "bar-cli"]) == 0
    finally:
        os.chdir(here)
    return folder, namespace


def test_the_session_runs_and_its_answers_hold(ran):
    folder, namespace = ran
    commands, poses = namespace["commands"], namespace["poses"]
    assert commands.status == ("ok", "ok")
    calibrated = folder / "bar-python"
    reached = rc.fk(namespace["robot"], commands.joints, calibrated=calibrated)
    assert np.abs(reached[:, :3] - poses[:, :3]).max() < 1e-6  # mm
    # Seeded with the readings, the branch is kept: the joints come back as given.
    assert np.allclose(commands.joints, namespace["q"], rtol=0, atol=1e-6)  # deg
    assert namespace["tracked"].status == ("ok",) * 8
    assert len(namespace["planned"].rows) == 10 * 4  # ten bar placements, four touches


def test_the_session_calibrates_as_robocal_calibrate(ran):
    folder, _ = ran
    by_python = json.loads((folder / "bar-python" / "result.json").read_text())
    by_cli = json.loads((folder / "bar-cli" / "result.json").read_text())
    assert [p["estimate"] for p in by_python["parameters"]] == pytest.approx(
        [p["estimate"] for p in by_cli["parameters"]], rel=1e-9, abs=1e-12)
    assert (folder / "bar-python" / "robot_calibrated.yaml").read_text() == \
        (folder / "bar-cli" / "robot_calibrated.yaml").read_text()
