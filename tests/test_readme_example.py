"""The README's worked example runs as written, prints what the README shows, and finds
the errors it put in.

Text and whole numbers (counts) must match exactly. Figures computed by the solver are
compared within the spread the estimator itself has, so that another version of a
library, whose last digits differ, passes, while a change to what the code computes
does not:

* an RMS, a condition number and a standard error scale with the noise estimate, whose
  relative spread from m measurements and p fitted parameters is 1/sqrt(2 (m - p));
* an estimate within a tenth of its standard error (plus half a unit of the last digit
  printed): solvers that agree to their tolerance land far closer than that, while a
  different fit moves it by a sizeable part of its standard error.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import re
import shlex
from pathlib import Path

import pytest

from robocal_casadi.cli import main

README = Path(__file__).resolve().parents[1] / "README.md"
NUMBER = re.compile(r"(?<![\w.])[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?(?!\w)")
ESTIMATE = re.compile(r"(\w+) ([-+]\d+\.\d+) \+- (\d+\.\d+) (mm|deg)")


def section() -> str:
    return README.read_text().split("## A worked example", 1)[1].split("\n## ", 1)[0]


def worked_example_commands() -> list[list[str]]:
    """The robocal commands of the README's worked example, variables expanded."""
    block = section().split("```bash", 1)[1].split("```", 1)[0]
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


def printed_lines() -> list[str]:
    """The lines the README says the last command prints."""
    after = section().split("where the last command prints", 1)[1]
    return after.split("```", 2)[1].strip("\n").splitlines()


def estimates_sentence() -> dict[str, tuple[float, float, str]]:
    """name -> (change from nominal, standard error, unit) as the README gives them."""
    text = " ".join(section().split("bar-result/result.json` gives", 1)[1].split())
    return {m[1]: (float(m[2]), float(m[3]), m[4]) for m in ESTIMATE.finditer(text)}


def skeleton(line: str) -> tuple[str, list[str]]:
    """The line with each number replaced by '#', and the numbers as written."""
    return NUMBER.sub("#", line), NUMBER.findall(line)


def half_digit(text: str) -> float:
    """Half a unit of the last digit of a number as printed."""
    decimals = len(text.split(".")[1]) if "." in text else 0
    return 0.5 * 10.0 ** -decimals


def compare_lines(expected: list[str], actual: list[str], relative: float) -> None:
    assert len(actual) == len(expected), "\n".join(actual)
    for want, got in zip(expected, actual):
        (want_text, want_numbers), (got_text, got_numbers) = skeleton(want), skeleton(got)
        assert got_text == want_text, f"README: {want}\nprinted: {got}"
        for a, b in zip(want_numbers, got_numbers):
            if "." not in a and "e" not in a.lower():
                assert a == b, f"README: {want}\nprinted: {got}"
            else:
                assert float(b) == pytest.approx(float(a), rel=relative,
                                                 abs=half_digit(a)), f"README: {want}\n" \
                                                                     f"printed: {got}"


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> tuple[Path, list[str]]:
    folder = tmp_path_factory.mktemp("readme")
    commands = worked_example_commands()
    assert [c[0] for c in commands] == ["simulate", "simulate", "calibrate"]
    capture = []
    here = os.getcwd()
    os.chdir(folder)
    try:
        for command in commands:
            buffer = io.StringIO()
            with contextlib.redirect_stdout(buffer):
                assert main(command) == 0
            capture = buffer.getvalue().splitlines()
    finally:
        os.chdir(here)
    return folder, capture


def spread(lines: list[str]) -> float:
    """Relative spread of the noise estimate, 1/sqrt(2 (m - p)), from the first line."""
    m, p = (int(v) for v in re.match(r"(\d+) measurements.*?; (\d+) of", lines[0]).groups())
    return 1.0 / math.sqrt(2.0 * (m - p))


def test_prints_what_the_readme_shows(run):
    _, printed = run
    expected = printed_lines()
    compare_lines(expected, printed, spread(expected))


def test_estimates_are_those_the_readme_gives(run):
    folder, _ = run
    relative = spread(printed_lines())
    result = json.loads((folder / "bar-result" / "result.json").read_text())
    rows = {entry["name"]: entry for entry in result["parameters"]}
    given = estimates_sentence()
    assert set(given) == {"a2", "alpha3", "d4", "theta5"}
    for name, (change, std, unit) in given.items():
        entry = rows[name]
        assert entry["unit"] == unit
        assert entry["std"] == pytest.approx(std, rel=relative, abs=half_digit(f"{std}"))
        assert entry["estimate"] - entry["nominal"] == pytest.approx(
            change, abs=0.1 * entry["std"] + half_digit(f"{change}")), name


def test_finds_the_errors_it_put_in(run):
    folder, _ = run
    truth = {"a2": 0.3, "alpha3": 0.02, "d4": -0.2, "theta5": 0.03}  # as the README says
    result = json.loads((folder / "bar-result" / "result.json").read_text())
    for entry in result["parameters"]:
        if entry["name"] in truth:
            assert entry["identifiable"]
            change = entry["estimate"] - entry["nominal"]
            assert change == pytest.approx(truth[entry["name"]], abs=3 * entry["std"])


def test_the_comparison_can_fail():
    """A README figure off by more than the spread, or other text, is caught."""
    lines = ["180 measurements from dataset.yaml; 21 of 45 parameters identifiable "
             "(condition number 17.93)", "fit RMS [mm]: nominal 0.1984, geometric 0.01539"]
    relative = spread(lines)
    compare_lines(lines, [lines[0].replace("17.93", "17.95"), lines[1]], relative)
    for wrong in ([lines[0].replace("21 of", "19 of"), lines[1]],
                  [lines[0], lines[1].replace("0.01539", "0.01700")],
                  [lines[0], lines[1].replace("geometric", "final")],
                  lines[:1]):
        with pytest.raises(AssertionError):
            compare_lines(lines, wrong, relative)
