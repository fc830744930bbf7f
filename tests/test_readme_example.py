"""The README's worked example runs as written and finds the errors it put in."""

from __future__ import annotations

import json
import re
import shlex
from pathlib import Path

import pytest

from robocal_casadi.cli import main

README = Path(__file__).resolve().parents[1] / "README.md"


def worked_example_commands() -> list[list[str]]:
    """The robocal commands of the README's worked example, variables expanded."""
    text = README.read_text()
    block = text.split("## A worked example", 1)[1].split("```bash", 1)[1].split("```", 1)[0]
    block = block.replace("\\\n", " ")
    variables, commands = {}, []
    for line in block.splitlines():
        line = line.split("  #", 1)[0].strip()
        if not line:
            continue
        assignment = re.fullmatch(r'(\w+)="(.*)"', line)
        if assignment:
            variables[assignment.group(1)] = assignment.group(2)
            continue
        for name, value in variables.items():
            line = line.replace(f"${name}", value)
        words = shlex.split(line)
        assert words[0] == "robocal"
        commands.append(words[1:])
    return commands


def test_worked_example(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    commands = worked_example_commands()
    assert [c[0] for c in commands] == ["simulate", "simulate", "calibrate"]
    for command in commands:
        assert main(command) == 0
    truth = {"a2": 0.3, "alpha3": 0.02, "d4": -0.2, "theta5": 0.03}  # as the README says
    result = json.loads((tmp_path / "bar-result" / "result.json").read_text())
    for entry in result["parameters"]:
        if entry["name"] in truth:
            assert entry["identifiable"]
            change = entry["estimate"] - entry["nominal"]
            assert change == pytest.approx(truth[entry["name"]], abs=3 * entry["std"])
    assert "validation RMS [mm]" in capsys.readouterr().out
