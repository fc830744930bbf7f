"""Broken input files of every kind, through every verb, end cleanly.

Valid files come from the simulator (a 6R in mm/deg, a 7-DOF in m/rad) and a small
tracking job; each case breaks one thing and runs the real verb in-process. Every case
must end with exit status 2, exactly one line on standard error that names the broken
file and the key or line, and say what is wrong, and must leave no output behind (not
the requested file or folder, nor a staging file beside it).

A second group checks what is deliberately tolerated (byte-order mark, Windows line
endings, quoted cells, spaces, blank lines, trailing commas): such a table must read
back to exactly the same numbers as the clean one, and line numbers in later messages
must still be the file's own.
"""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal_casadi.cli import main
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import ROBOTS
from robocal_casadi.model.robot import save_robot

REPOSITORY = Path(__file__).resolve().parents[1]

# ----------------------------------------------------------------------------- templates


def _write_job(folder: Path) -> None:
    """A valid tracking job for the 6R (mm/deg): capture joints inside the limits and a
    target straight ahead of the camera at the standoff."""
    folder.mkdir(parents=True)
    save_robot(ROBOTS["industrial_6r"](), folder / "robot.yaml")
    lines = ["time,q1,q2,q3,q4,q5,q6,x,y,z,roll,pitch,yaw"]
    for k in range(4):
        lines.append(f"{0.01 * k},{5 + k},-80,90,0,{40 + k},0,0,0,300,0,0,0")
    (folder / "observations.csv").write_text("\n".join(lines) + "\n")
    (folder / "job.yaml").write_text(
        "kind: tracking\nrobot: robot.yaml\nunits: {length: mm, angle: deg}\n"
        "camera: {xyz: [0, 0, 50]}\nstandoff: 300.0\nup: [0, 0, 1]\n"
        "data: observations.csv\n")


@pytest.fixture(scope="module")
def templates(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("valid")
    six, seven = ROBOTS["industrial_6r"](), ROBOTS["panda_7dof"]()
    simulate(six, "cross_bar", rows=3, seed=1, out_dir=root / "bar", progress=False)
    simulate(six, "artifact_touches", rows=2, sockets=3, touches=2, seed=1,
             out_dir=root / "art", progress=False)
    simulate(six, "sphere_laser", rows=6, seed=1, out_dir=root / "sphere", progress=False)
    simulate(six, "sphere_laser", rows=6, seed=1, readings="pendant",
             out_dir=root / "pendant", progress=False)
    simulate(seven, "tracker_points", rows=6, seed=1, out_dir=root / "tracker", progress=False)
    _write_job(root / "job")
    (root / "targets").mkdir()
    save_robot(six, root / "targets" / "robot.yaml")
    (root / "targets" / "targets.csv").write_text(
        "x,y,z,qw,qx,qy,qz\n900,0,1200,0,1,0,0\n850,100,1100,0,1,0,0\n")
    return root


# ----------------------------------------------------------------------------- editing


def yaml_set(name: str, path: tuple, value=None, *, delete: bool = False) -> Callable:
    """Set (or delete) ``path`` in the YAML file ``name``."""

    def change(folder: Path) -> None:
        content = yaml.safe_load((folder / name).read_text())
        node = content
        for key in path[:-1]:
            node = node[key]
        if delete:
            del node[path[-1]]
        else:
            node[path[-1]] = value
        (folder / name).write_text(yaml.safe_dump(content, sort_keys=False))

    return change


def write(name: str, text: str | bytes) -> Callable:
    def change(folder: Path) -> None:
        if isinstance(text, bytes):
            (folder / name).write_bytes(text)
        else:
            (folder / name).write_text(text)

    return change


def append(name: str, text: str | bytes) -> Callable:
    def change(folder: Path) -> None:
        with (folder / name).open("ab") as handle:
            handle.write(text if isinstance(text, bytes) else text.encode())

    return change


def replace(name: str, old: str, new: str, count: int = 1) -> Callable:
    def change(folder: Path) -> None:
        text = (folder / name).read_text()
        assert old in text, (old, text[:200])
        (folder / name).write_text(text.replace(old, new, count))

    return change


def cell(name: str, line: int, column: str, value: str) -> Callable:
    """Set one cell (``line`` is the file line, the header being line 1)."""

    def change(folder: Path) -> None:
        lines = (folder / name).read_text().splitlines()
        header = lines[0].split(",")
        cells = lines[line - 1].split(",")
        cells[header.index(column)] = value
        lines[line - 1] = ",".join(cells)
        (folder / name).write_text("\n".join(lines) + "\n")

    return change


def columns(name: str, drop: tuple = (), add: dict | None = None) -> Callable:
    """Drop columns and append others (``add``: name -> value of every row)."""

    def change(folder: Path) -> None:
        lines = (folder / name).read_text().splitlines()
        header = lines[0].split(",")
        keep = [k for k, c in enumerate(header) if c not in drop]
        out = []
        for i, line in enumerate(lines):
            cells = line.split(",")
            row = [cells[k] for k in keep]
            for column, value in (add or {}).items():
                row.append(column if i == 0 else value)
            out.append(",".join(row))
        (folder / name).write_text("\n".join(out) + "\n")

    return change


def drop_lines(name: str, predicate: Callable[[str], bool]) -> Callable:
    def change(folder: Path) -> None:
        lines = (folder / name).read_text().splitlines()
        kept = [lines[0]] + [line for line in lines[1:] if not predicate(line)]
        assert len(kept) < len(lines)
        (folder / name).write_text("\n".join(kept) + "\n")

    return change


# Nine levels of nine aliases each: 9**9 (387 million) strings once expanded, in a file
# of a few hundred bytes; as top-level keys, and as one flow mapping for any value.
_LEVELS = ["a: &a [x, x, x, x, x, x, x, x, x]"] + [
    f"{chr(98 + k)}: &{chr(98 + k)} [{', '.join(['*' + chr(97 + k)] * 9)}]" for k in range(8)]
ALIAS_BOMB = "\n".join(_LEVELS) + "\n"
ALIAS_BOMB_VALUE = "{" + ", ".join(_LEVELS) + "}"


def grow(name: str, size: int) -> Callable:
    """Make ``name`` ``size`` bytes long (sparse: no disk space is used)."""

    def change(folder: Path) -> None:
        with (folder / name).open("r+b") as handle:
            handle.truncate(size)

    return change


def symlink_loop(name: str, replace_existing: bool = False) -> Callable:
    """``name`` becomes one of two symbolic links pointing at each other."""

    def change(folder: Path) -> None:
        if replace_existing:
            (folder / name).unlink()
        (folder / name).symlink_to(f"{name}.other")
        (folder / f"{name}.other").symlink_to(name)

    return change


def link(name: str, target: str) -> Callable:
    def change(folder: Path) -> None:
        (folder / name).symlink_to(target)

    return change


def fifo(name: str, replace_existing: bool = False) -> Callable:
    """``name`` becomes a named pipe no one writes to: reading it would wait forever."""

    def change(folder: Path) -> None:
        if replace_existing:
            (folder / name).unlink()
        os.mkfifo(folder / name)

    return change


def both(*changes: Callable) -> Callable:
    def change(folder: Path) -> None:
        for c in changes:
            c(folder)

    return change


# ----------------------------------------------------------------------------- verbs


def argv(verb: str, folder: Path, out: Path) -> list[str]:
    """The command line of ``verb`` on the files in ``folder``, writing ``out``."""
    if verb == "calibrate":
        return ["calibrate", str(folder / "dataset.yaml"), "--out", str(out), "--no-diagnose",
                "--no-report"]
    if verb == "plan":
        return ["plan", str(folder / "dataset.yaml"), "--count", "8", "--out", str(out),
                "--no-refine"]
    if verb == "fk":
        table = next(p for p in ("touches.csv", "scan.csv", "points.csv")
                     if (folder / p).exists())
        return ["fk", str(folder / "robot.yaml"), str(folder / table), "--out", str(out)]
    if verb == "simulate":
        return ["simulate", "--robot", str(folder / "robot.yaml"), "--kind", "tracker_points",
                "--rows", "3", "--out", str(out)]
    if verb == "track":
        return ["track", str(folder / "job.yaml"), "--out", str(out)]
    if verb == "compensate":
        return ["compensate", str(folder / "robot.yaml"), str(folder / "targets.csv"), "--out",
                str(out), "--restarts", "0"]
    raise AssertionError(verb)


OUTPUT_NAME = {"calibrate": "result", "simulate": "sim"}

# (id, template, verb, change, fragments the one line must hold)
CASES = [
    # --- robot files
    ("robot empty", "bar", "fk", write("robot.yaml", ""), ["robot.yaml", "empty"]),
    ("robot only a scalar", "bar", "fk", write("robot.yaml", "42\n"),
     ["robot.yaml", "mapping", "42"]),
    ("robot a list", "bar", "fk", write("robot.yaml", "- 1\n- 2\n"), ["robot.yaml", "a list"]),
    ("robot bad YAML", "bar", "fk", write("robot.yaml", "name: x\njoints: [1, 2\n"),
     ["robot.yaml", "line", "not valid YAML"]),
    ("robot duplicate key", "bar", "fk", append("robot.yaml", "convention: mdh\n"),
     ["robot.yaml", "line", "duplicate key 'convention' (first on line 2)"]),
    ("robot duplicate key in a joint", "bar", "fk",
     replace("robot.yaml", "  d: 675.0\n", "  d: 675.0\n  d: 676.0\n"),
     ["robot.yaml", "line", "duplicate key 'd'"]),
    ("robot unknown top-level key", "bar", "fk", yaml_set("robot.yaml", ("joint_count",), 6),
     ["robot.yaml", "joint_count", "unknown key", "allowed"]),
    ("robot units missing", "bar", "fk", yaml_set("robot.yaml", ("units",), delete=True),
     ["robot.yaml", "units", "missing"]),
    ("robot units misspelt key", "bar", "fk",
     yaml_set("robot.yaml", ("units",), {"lenght": "mm", "angle": "deg"}),
     ["robot.yaml", "units.lenght", "unknown key"]),
    ("robot units list", "bar", "fk", yaml_set("robot.yaml", ("units", "length"), ["mm"]),
     ["robot.yaml", "units.length", "['mm']"]),
    ("robot units a string", "bar", "fk", yaml_set("robot.yaml", ("units",), "mm"),
     ["robot.yaml", "units", "mapping"]),
    ("robot convention a list", "bar", "fk", yaml_set("robot.yaml", ("convention",), ["dh"]),
     ["robot.yaml", "convention"]),
    ("robot joints a mapping", "bar", "fk", yaml_set("robot.yaml", ("joints",), {"a": 1}),
     ["robot.yaml", "joints", "list"]),
    ("robot joints empty", "bar", "simulate", yaml_set("robot.yaml", ("joints",), []),
     ["robot.yaml", "joints", "non-empty"]),
    ("robot joint a list", "bar", "fk", yaml_set("robot.yaml", ("joints", 1), [1, 2]),
     ["robot.yaml", "joints[1] (joint 2)", "mapping"]),
    ("robot joint missing alpha", "bar", "simulate",
     yaml_set("robot.yaml", ("joints", 3, "alpha"), delete=True),
     ["robot.yaml", "joints[3] (joint 4).alpha", "missing"]),
    ("robot joint value null", "bar", "fk", yaml_set("robot.yaml", ("joints", 2, "d"), None),
     ["robot.yaml", "joints[2] (joint 3).d", "expected a number"]),
    ("robot limits of length 3", "bar", "fk",
     yaml_set("robot.yaml", ("joints", 0, "limits"), [-1, 0, 1]),
     ["robot.yaml", "joints[0] (joint 1).limits", "2 numbers"]),
    ("robot limits reversed", "bar", "fk",
     yaml_set("robot.yaml", ("joints", 0, "limits"), [10, -10]),
     ["robot.yaml", "joints[0] (joint 1).limits", "not below"]),
    ("robot limits nested null", "bar", "fk",
     yaml_set("robot.yaml", ("joints", 0, "limits"), [None, None]),
     ["robot.yaml", "joints[0] (joint 1).limits[0]", "expected a number"]),
    ("robot joint type misspelt", "bar", "fk",
     yaml_set("robot.yaml", ("joints", 2, "type"), "prismatc"),
     ["robot.yaml", "joints[2] (joint 3).type", "'prismatc'"]),
    ("robot joint unknown key", "bar", "fk",
     yaml_set("robot.yaml", ("joints", 2, "offset"), 0),
     ["robot.yaml", "joints[2] (joint 3)", "'offset'"]),
    ("robot a huge length", "bar", "fk", yaml_set("robot.yaml", ("joints", 1, "a"), 1e300),
     ["robot.yaml", "joints[1] (joint 2).a", "implausibly large"]),
    ("robot base rpy of length 2", "bar", "fk",
     yaml_set("robot.yaml", ("base",), {"xyz": [0, 0, 0], "rpy": [0, 0]}),
     ["robot.yaml", "base.rpy", "3 numbers"]),
    ("robot base unknown key", "bar", "fk",
     yaml_set("robot.yaml", ("base",), {"position": [0, 0, 0]}),
     ["robot.yaml", "base.position", "unknown key"]),
    ("robot tool a list", "bar", "fk", yaml_set("robot.yaml", ("tool",), [0, 0, 100]),
     ["robot.yaml", "tool", "mapping"]),
    ("robot gravity text", "bar", "fk", yaml_set("robot.yaml", ("gravity",), "down"),
     ["robot.yaml", "gravity", "3 numbers"]),
    ("robot mass negative", "bar", "simulate",
     yaml_set("robot.yaml", ("joints", 1), {"type": "revolute", "theta": -90, "d": 0, "a": 680,
                                            "alpha": 0, "mass": -2, "com": [0, 0, 0]}),
     ["robot.yaml", "joints[1] (joint 2).mass", "negative"]),
    ("robot com of length 2", "bar", "fk",
     yaml_set("robot.yaml", ("joints", 1), {"type": "revolute", "theta": -90, "d": 0, "a": 680,
                                            "alpha": 0, "mass": 2, "com": [0, 0]}),
     ["robot.yaml", "joints[1] (joint 2).com", "3 numbers"]),
    ("robot mass without com", "bar", "fk",
     yaml_set("robot.yaml", ("joints", 1), {"type": "revolute", "theta": -90, "d": 0, "a": 680,
                                            "alpha": 0, "mass": 2}),
     ["robot.yaml", "joints[1] (joint 2).com", "without"]),
    ("robot not UTF-8", "bar", "fk", write("robot.yaml", b"name: r\xe9bot\n"),
     ["robot.yaml", "line 1", "UTF-8"]),
    ("robot file is a dataset", "bar", "fk",
     lambda f: shutil.copy(f / "dataset.yaml", f / "robot.yaml"),
     ["robot.yaml", "this is a dataset file"]),
    # --- a dataset's robot file
    ("dataset robot missing", "bar", "calibrate", lambda f: (f / "robot.yaml").unlink(),
     ["dataset.yaml", "robot", "robot.yaml", "not found"]),
    ("dataset robot broken", "bar", "calibrate",
     yaml_set("robot.yaml", ("joints", 2, "d"), delete=True),
     ["robot.yaml", "joints[2] (joint 3).d", "missing"]),
    ("dataset robot key a list", "bar", "calibrate", yaml_set("dataset.yaml", ("robot",), [1]),
     ["dataset.yaml", "robot", "file name"]),
    # --- dataset files
    ("dataset empty", "bar", "calibrate", write("dataset.yaml", ""), ["dataset.yaml", "empty"]),
    ("dataset only a scalar", "bar", "calibrate", write("dataset.yaml", "cross_bar\n"),
     ["dataset.yaml", "mapping"]),
    ("dataset kind missing", "bar", "calibrate", yaml_set("dataset.yaml", ("kind",), delete=True),
     ["dataset.yaml", "kind", "missing"]),
    ("dataset kind unknown", "bar", "calibrate", yaml_set("dataset.yaml", ("kind",), "bar"),
     ["dataset.yaml", "kind", "'bar'"]),
    ("dataset unknown top-level key", "bar", "calibrate",
     yaml_set("dataset.yaml", ("probe_offset",), [0, 0, 1]),
     ["dataset.yaml", "probe_offset", "unknown key", "allowed"]),
    ("dataset misspelt optional key", "sphere", "calibrate",
     yaml_set("dataset.yaml", ("sphere", "center_guess"), [0, 0, 0]),
     ["dataset.yaml", "sphere.center_guess", "unknown key"]),
    ("dataset duplicate key", "bar", "calibrate", append("dataset.yaml", "data: other.csv\n"),
     ["dataset.yaml", "line", "duplicate key 'data'"]),
    ("dataset units missing", "bar", "calibrate",
     yaml_set("dataset.yaml", ("units",), delete=True), ["dataset.yaml", "units", "missing"]),
    ("dataset angle unit misspelt", "bar", "calibrate",
     yaml_set("dataset.yaml", ("units", "angle"), "degrees"),
     ["dataset.yaml", "units.angle", "'degrees'"]),
    ("dataset units nested null", "bar", "calibrate",
     yaml_set("dataset.yaml", ("units", "length"), None),
     ["dataset.yaml", "units.length", "no length unit"]),
    ("bar length negative", "bar", "calibrate", yaml_set("dataset.yaml", ("bar", "length"), -400),
     ["dataset.yaml", "bar.length", "positive"]),
    ("bar length text", "bar", "calibrate", yaml_set("dataset.yaml", ("bar", "length"), "400mm"),
     ["dataset.yaml", "bar.length", "expected a number"]),
    ("bar length huge", "bar", "calibrate", yaml_set("dataset.yaml", ("bar", "length"), 1e300),
     ["dataset.yaml", "bar.length", "implausibly large"]),
    ("bar block a list", "bar", "calibrate", yaml_set("dataset.yaml", ("bar",), [400]),
     ["dataset.yaml", "bar", "mapping"]),
    ("probe xyz of length 2", "bar", "calibrate",
     yaml_set("dataset.yaml", ("probe", "xyz"), [0, 150]), ["dataset.yaml", "probe.xyz", "3"]),
    ("probe xyz nested nulls", "bar", "calibrate",
     yaml_set("dataset.yaml", ("probe", "xyz"), [None, None, None]),
     ["dataset.yaml", "probe.xyz[0]", "expected a number"]),
    ("data key a list", "bar", "calibrate", yaml_set("dataset.yaml", ("data",), ["a.csv"]),
     ["dataset.yaml", "data", "file name"]),
    ("data table missing", "bar", "calibrate", yaml_set("dataset.yaml", ("data",), "nowhere.csv"),
     ["dataset.yaml", "data", "nowhere.csv", "not found"]),
    ("payload_com of length 2", "tracker", "calibrate",
     yaml_set("dataset.yaml", ("payload_com",), [0, 0]), ["dataset.yaml", "payload_com", "3"]),
    ("artifact distance to an untouched socket", "art", "calibrate",
     yaml_set("dataset.yaml", ("artifact", "distances", 0), ["hole_0", "hole_9", 50.0]),
     ["dataset.yaml", "artifact", "hole_9", "never touched"]),
    ("artifact distance of two items", "art", "calibrate",
     yaml_set("dataset.yaml", ("artifact", "distances", 0), ["hole_0", "hole_1"]),
     ["dataset.yaml", "artifact.distances[0]", "[socket, socket, length]"]),
    ("artifact distance to itself", "art", "calibrate",
     yaml_set("dataset.yaml", ("artifact", "distances", 0), ["hole_0", "hole_0", 50.0]),
     ["dataset.yaml", "artifact.distances[0]", "itself"]),
    ("artifact distance negative", "art", "calibrate",
     yaml_set("dataset.yaml", ("artifact", "distances", 0), ["hole_0", "hole_1", -50.0]),
     ["dataset.yaml", "artifact.distances[0][2]", "positive"]),
    ("artifact distance given twice", "art", "calibrate",
     yaml_set("dataset.yaml", ("artifact", "distances", 1), ["hole_1", "hole_0", 51.0]),
     ["dataset.yaml", "artifact.distances[1]", "twice"]),
    ("artifact distances a number", "art", "calibrate",
     yaml_set("dataset.yaml", ("artifact", "distances"), 50),
     ["dataset.yaml", "artifact.distances", "list"]),
    ("artifact perpendicular of three", "art", "calibrate",
     yaml_set("dataset.yaml", ("artifact", "perpendicular"), [["hole_0", "hole_1", "hole_2"]]),
     ["dataset.yaml", "artifact.perpendicular[0]", "[A, C, B, D]"]),
    ("artifact socket name a list", "art", "calibrate",
     yaml_set("dataset.yaml", ("artifact", "distances", 0), [["hole_0"], "hole_1", 50.0]),
     ["dataset.yaml", "artifact.distances[0][0]", "socket name"]),
    ("sphere radius zero", "sphere", "calibrate",
     yaml_set("dataset.yaml", ("sphere", "radius"), 0),
     ["dataset.yaml", "sphere.radius", "positive"]),
    ("sphere block missing", "sphere", "calibrate",
     yaml_set("dataset.yaml", ("sphere",), delete=True), ["dataset.yaml", "sphere", "missing"]),
    ("laser direction zero", "sphere", "calibrate",
     yaml_set("dataset.yaml", ("laser", "direction_guess"), [0, 0, 0]),
     ["dataset.yaml", "laser.direction_guess", "non-zero"]),
    ("laser block a number", "sphere", "calibrate", yaml_set("dataset.yaml", ("laser",), 0),
     ["dataset.yaml", "laser", "mapping"]),
    ("tracker target missing", "tracker", "calibrate",
     yaml_set("dataset.yaml", ("target",), delete=True), ["dataset.yaml", "target", "missing"]),
    ("plan on a broken dataset", "tracker", "plan",
     yaml_set("dataset.yaml", ("instrument", "xyz"), [0, 0]),
     ["dataset.yaml", "instrument.xyz", "3"]),
    ("planning tilt negative", "bar", "plan",
     yaml_set("dataset.yaml", ("planning",), {"max_tilt": -5}),
     ["dataset.yaml", "planning.max_tilt", "above 0"]),
    ("planning touches not whole", "art", "plan",
     yaml_set("dataset.yaml", ("planning",), {"touches_per_socket": 1.5}),
     ["dataset.yaml", "planning.touches_per_socket", "1.5"]),
    # --- data tables
    ("table header only", "bar", "calibrate",
     lambda f: (f / "touches.csv").write_text((f / "touches.csv").read_text().splitlines()[0]),
     ["touches.csv", "empty table"]),
    ("table empty", "bar", "calibrate", write("touches.csv", ""), ["touches.csv", "no header"]),
    ("table separated by semicolons", "bar", "calibrate",
     lambda f: (f / "touches.csv").write_text((f / "touches.csv").read_text().replace(",", ";")),
     ["touches.csv", "line 1", "comma-separated"]),
    ("table without a header", "bar", "calibrate",
     lambda f: (f / "touches.csv").write_text(
         "\n".join((f / "touches.csv").read_text().splitlines()[1:]).replace(",A,", ",1,")),
     ["touches.csv", "line 1", "header"]),
    ("table duplicate column", "tracker", "calibrate", columns("points.csv", add={"q3": "0.1"}),
     ["points.csv", "line 1", "'q3'", "more than once"]),
    ("table missing joint column", "bar", "calibrate", columns("touches.csv", drop=("q3",)),
     ["touches.csv", "line 1", "'q3'"]),
    ("table joint columns in capitals", "bar", "calibrate",
     replace("touches.csv", "q1,q2", "Q1,q2"), ["touches.csv", "'Q1'", "case-sensitive"]),
    ("table extra joint column", "bar", "calibrate", columns("touches.csv", add={"q7": "0"}),
     ["touches.csv", "line 1", "'q7'", "beyond"]),
    ("table NaN cell", "bar", "calibrate", cell("touches.csv", 4, "q2", "nan"),
     ["touches.csv", "line 4", "'q2'", "finite"]),
    ("table infinite cell", "tracker", "calibrate", cell("points.csv", 3, "x", "-inf"),
     ["points.csv", "line 3", "'x'", "finite"]),
    ("table empty cell", "bar", "calibrate", cell("touches.csv", 5, "q6", ""),
     ["touches.csv", "line 5", "'q6'", "empty cell"]),
    ("table decimal comma", "bar", "calibrate", cell("touches.csv", 3, "q1", '"12,5"'),
     ["touches.csv", "line 3", "'q1'", "decimal separator"]),
    ("table underscore in a number", "bar", "calibrate", cell("touches.csv", 3, "q1", "1_0"),
     ["touches.csv", "line 3", "'q1'", "'1_0'"]),
    ("table huge measured value", "tracker", "calibrate", cell("points.csv", 4, "y", "1e300"),
     ["points.csv", "line 4", "'y'", "implausibly large"]),
    ("tracker point far from the others", "tracker", "calibrate",
     cell("points.csv", 4, "x", "5000"),
     ["points.csv", "line 4", "farther than the robot can carry its target"]),
    ("table row too short", "bar", "calibrate", replace("touches.csv", "\n1,A,", "\n1,A,\n1,A,"),
     ["touches.csv", "cells"]),
    ("table not UTF-8", "bar", "calibrate", append("touches.csv", b"0,A,\xe9\n"),
     ["touches.csv", "line 14", "UTF-8"]),
    ("table NUL byte", "bar", "calibrate", append("touches.csv", "0,A,\x00\n"),
     ["touches.csv", "NUL"]),
    ("table unnamed column with values", "bar", "calibrate",
     lambda f: (f / "touches.csv").write_text(
         "\n".join(line + ("," if i == 0 else ",7")
                   for i, line in enumerate((f / "touches.csv").read_text().splitlines()))),
     ["touches.csv", "line 2", "no name"]),
    ("table degrees in a rad file", "tracker", "calibrate", cell("points.csv", 5, "q2", "95"),
     ["points.csv", "line 5", "q2", "degrees in a file that declares rad"]),
    ("pose id not whole", "bar", "calibrate", cell("touches.csv", 2, "pose", "0.5"),
     ["touches.csv", "line 2", "'pose'", "whole-number"]),
    ("pose id text", "bar", "calibrate", cell("touches.csv", 2, "pose", "first"),
     ["touches.csv", "line 2", "'pose'"]),
    ("pose id huge", "bar", "calibrate", cell("touches.csv", 2, "pose", "1e300"),
     ["touches.csv", "line 2", "'pose'"]),
    ("bar point unknown", "bar", "calibrate", cell("touches.csv", 3, "point", "E"),
     ["touches.csv", "line 3", "'point'", "'E'"]),
    ("bar pose with three touches", "bar", "calibrate",
     drop_lines("touches.csv", lambda line: line.startswith("1,C,")),
     ["touches.csv", "pose 1", "missing ['C']"]),
    ("artifact socket touched once", "art", "calibrate", cell("touches.csv", 3, "point", "hole_O"),
     ["touches.csv", "line 3", "'hole_O'", "only once"]),
    ("sphere distance column missing", "sphere", "calibrate",
     columns("scan.csv", drop=("distance",)), ["scan.csv", "'distance'"]),
    ("pendant quaternion not unit", "pendant", "calibrate", cell("scan.csv", 3, "qw", "0.9"),
     ["scan.csv", "line 3", "quaternion", "norm"]),
    ("pendant quaternion zero", "pendant", "calibrate",
     both(*(cell("scan.csv", 2, c, "0") for c in ("qw", "qx", "qy", "qz"))),
     ["scan.csv", "line 2", "norm 0"]),
    ("pendant table with joint columns", "pendant", "calibrate",
     columns("scan.csv", add={"q1": "0"}), ["scan.csv", "both", "q1"]),
    ("pendant table missing qz", "pendant", "calibrate", columns("scan.csv", drop=("qz",)),
     ["scan.csv", "'qz'"]),
    ("tracker table without z", "tracker", "calibrate", columns("points.csv", drop=("z",)),
     ["points.csv", "'z'"]),
    ("payload negative", "tracker", "calibrate", columns("points.csv", add={"payload": "-2"}),
     ["points.csv", "line 2", "'payload'", "negative"]),
    ("temperature not a number", "tracker", "calibrate",
     columns("points.csv", add={"temperature": "warm"}), ["points.csv", "'temperature'"]),
    ("fk reading outside the limits", "bar", "fk", cell("touches.csv", 6, "q5", "400"),
     ["touches.csv", "line 6", "q5", "limits", "robot.yaml"]),
    # --- tracking jobs
    ("job standoff missing", "job", "track", yaml_set("job.yaml", ("standoff",), delete=True),
     ["job.yaml", "standoff", "missing"]),
    ("job standoff negative", "job", "track", yaml_set("job.yaml", ("standoff",), -300),
     ["job.yaml", "standoff", "positive"]),
    ("job camera xyz of length 2", "job", "track",
     yaml_set("job.yaml", ("camera", "xyz"), [0, 50]), ["job.yaml", "camera.xyz", "3"]),
    ("job camera a list", "job", "track", yaml_set("job.yaml", ("camera",), [0, 0, 50]),
     ["job.yaml", "camera", "mapping"]),
    ("job up zero", "job", "track", yaml_set("job.yaml", ("up",), [0, 0, 0]),
     ["job.yaml", "up", "zero"]),
    ("job up text", "job", "track", yaml_set("job.yaml", ("up",), "z"), ["job.yaml", "up"]),
    ("job unknown key", "job", "track", yaml_set("job.yaml", ("stand_off",), 300),
     ["job.yaml", "stand_off", "unknown key"]),
    ("job duplicate key", "job", "track", append("job.yaml", "standoff: 200\n"),
     ["job.yaml", "line", "duplicate key 'standoff'"]),
    ("job table missing", "job", "track", yaml_set("job.yaml", ("data",), "none.csv"),
     ["job.yaml", "data", "none.csv", "not found"]),
    ("job robot broken", "job", "track", yaml_set("robot.yaml", ("units",), "mm"),
     ["robot.yaml", "units", "mapping"]),
    ("observations without yaw", "job", "track", columns("observations.csv", drop=("yaw",)),
     ["observations.csv", "'yaw'"]),
    ("observations time backwards", "job", "track", cell("observations.csv", 4, "time", "0"),
     ["observations.csv", "line 4", "time goes backwards"]),
    ("observation huge", "job", "track", cell("observations.csv", 3, "z", "1e300"),
     ["observations.csv", "line 3", "'z'", "implausibly large"]),
    ("observation NaN", "job", "track", cell("observations.csv", 3, "roll", "NaN"),
     ["observations.csv", "line 3", "'roll'", "finite"]),
    # --- targets
    ("targets without z", "targets", "compensate", columns("targets.csv", drop=("z",)),
     ["targets.csv", "'z'"]),
    ("targets with part of a quaternion", "targets", "compensate",
     columns("targets.csv", drop=("qx",)), ["targets.csv", "qx"]),
    ("targets quaternion zero", "targets", "compensate",
     both(*(cell("targets.csv", 3, c, "0") for c in ("qw", "qx", "qy", "qz"))),
     ["targets.csv", "line 3", "norm"]),
    ("targets huge", "targets", "compensate", cell("targets.csv", 2, "x", "1e300"),
     ["targets.csv", "line 2", "'x'", "implausibly large"]),
    # --- files built to exhaust memory or the stack, or numbers beyond any float
    ("robot alias bomb", "bar", "fk", write("robot.yaml", ALIAS_BOMB),
     ["robot.yaml", "aliases", "100,000"]),
    ("robot alias bomb as the name", "bar", "fk",
     replace("robot.yaml", "name: industrial-6r", "name: " + ALIAS_BOMB_VALUE),
     ["robot.yaml", "aliases"]),
    ("robot alias bomb as the joints", "bar", "fk",
     replace("robot.yaml", "joints:\n", "joints: [" + ALIAS_BOMB_VALUE + "]\nold_joints:\n"),
     ["robot.yaml", "aliases"]),
    ("dataset alias bomb as the kind", "tracker", "calibrate", write(
        "dataset.yaml", ALIAS_BOMB + "kind: *i\n"), ["dataset.yaml", "aliases"]),
    ("dataset nested 100k deep", "tracker", "calibrate",
     write("dataset.yaml", "kind: " + "[" * 100_000 + "]" * 100_000 + "\n"),
     ["dataset.yaml", "nested more than 100 levels"]),
    ("job nested mappings deep", "job", "track",
     write("job.yaml", "".join(f"{' ' * k}k{k}:\n" for k in range(300)) + " " * 300 + "x: 1\n"),
     ["job.yaml", "nested more than"]),
    ("dataset recursive alias", "tracker", "calibrate",
     replace("dataset.yaml", "target:\n", "loop: &r [*r]\ntarget:\n"),
     ["dataset.yaml", "contains it"]),
    ("robot 400-digit integer", "tracker", "fk",
     replace("robot.yaml", "d: 0.333", "d: " + "9" * 400), ["robot.yaml", "d", "too large"]),
    ("robot 5000-digit integer", "tracker", "fk",
     replace("robot.yaml", "d: 0.333", "d: " + "9" * 5000), ["robot.yaml", "cannot be read"]),
    ("dataset 400-digit integer", "tracker", "plan",
     replace("dataset.yaml", "xyz: [0.0, 0.0, 0.1]", "xyz: [0.0, 0.0, " + "1" * 400 + "]"),
     ["dataset.yaml", "target.xyz[2]", "too large"]),
    ("table 400-digit integer", "tracker", "calibrate", cell("points.csv", 3, "x", "7" * 400),
     ["points.csv", "line 3", "'x'", "too large"]),
    ("a 300 MiB table", "tracker", "calibrate", grow("points.csv", 300 * 2**20),
     ["points.csv", "MiB"]),
    ("a 5 MiB robot file", "tracker", "fk", grow("robot.yaml", 5 * 2**20),
     ["robot.yaml", "MiB"]),
    ("a long text value", "bar", "fk", replace("robot.yaml", "convention: dh",
                                               "convention: " + "x" * 100_000),
     ["robot.yaml", "convention"]),
    # --- a robot file declaring rad that holds degrees
    ("robot rad file with alpha in degrees", "tracker", "fk",
     replace("robot.yaml", "alpha: 0.0", "alpha: -90"),
     ["robot.yaml", "joints[0]", "alpha", "looks like degrees"]),
    ("robot rad file with theta in degrees", "tracker", "calibrate",
     replace("robot.yaml", "theta: 0.0", "theta: 180"),
     ["robot.yaml", "theta", "looks like degrees"]),
    ("robot rad file with limits in degrees", "tracker", "fk",
     replace("robot.yaml", "limits: [-2.8973, 2.8973]", "limits: [-166, 166]"),
     ["robot.yaml", "joints[0]", "limits", "looks like degrees"]),
    ("robot rad file with a tool rpy in degrees", "tracker", "fk",
     yaml_set("robot.yaml", ("tool", "rpy"), [0, 0, 45]),
     ["robot.yaml", "tool.rpy[2]", "looks like degrees"]),
    # --- links: loops, and tables outside the dataset's folder
    ("data a symlink loop", "tracker", "calibrate",
     both(symlink_loop("loop.csv"), replace("dataset.yaml", "data: points.csv", "data: loop.csv")),
     ["loop.csv", "loop of symbolic links"]),
    ("robot a symlink loop", "tracker", "calibrate",
     both(symlink_loop("loop.yaml"), replace("dataset.yaml", "robot: robot.yaml",
                                             "robot: loop.yaml")),
     ["loop.yaml", "loop of symbolic links"]),
    ("fk robot file a symlink loop", "bar", "fk",
     symlink_loop("robot.yaml", replace_existing=True),
     ["robot.yaml", "loop of symbolic links"]),
    ("data an absolute path", "tracker", "calibrate",
     replace("dataset.yaml", "data: points.csv", "data: /etc/passwd"),
     ["dataset.yaml", "data", "outside", "--allow-outside-data"]),
    ("data up the tree", "tracker", "plan",
     replace("dataset.yaml", "data: points.csv", "data: ../../../../../../etc/passwd"),
     ["dataset.yaml", "data", "outside", "--allow-outside-data"]),
    ("data a link out of the folder", "tracker", "calibrate",
     both(link("elsewhere.csv", "/etc/hostname"),
          replace("dataset.yaml", "data: points.csv", "data: elsewhere.csv")),
     ["dataset.yaml", "outside"]),
    ("job data outside", "job", "track",
     replace("job.yaml", "data: observations.csv", "data: /etc/passwd"),
     ["job.yaml", "data", "outside"]),
    ("data a named pipe", "tracker", "calibrate",
     both(fifo("pipe.csv"), replace("dataset.yaml", "data: points.csv", "data: pipe.csv")),
     ["pipe.csv", "pipe"]),
    ("robot file a named pipe", "bar", "fk", fifo("robot.yaml", replace_existing=True),
     ["robot.yaml", "pipe"]),
]


@pytest.mark.parametrize("template, verb, change, fragments",
                         [pytest.param(*case[1:], id=case[0]) for case in CASES])
def test_broken_input_is_refused_with_one_line_and_writes_nothing(
        templates, tmp_path, capsys, template, verb, change, fragments):
    folder = Path(shutil.copytree(templates / template, tmp_path / template))
    change(folder)
    out_parent = tmp_path / "out"
    out_parent.mkdir()
    out = out_parent / OUTPUT_NAME.get(verb, "out.csv")
    status = main(argv(verb, folder, out))
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert status == 2, err
    assert len(err.splitlines()) == 1, err
    assert err.startswith(f"robocal {verb}: error: "), err
    for fragment in fragments:
        assert fragment in err, f"{fragment!r} not in {err!r}"
    assert list(out_parent.iterdir()) == [], "an output or a staging file was left behind"


def test_every_template_is_valid(templates, tmp_path, capsys):
    """The cases above fail because of their one change: unchanged, the same files load
    and the quick verbs succeed."""
    for name in ("bar", "art", "sphere", "tracker"):
        assert load_dataset(templates / name / "dataset.yaml").rows > 0
    assert len(load_dataset(templates / "pendant" / "dataset.yaml").flange_poses) == 6
    assert main(argv("fk", templates / "bar", tmp_path / "poses.csv")) == 0
    assert main(argv("track", templates / "job", tmp_path / "joints.csv")) == 0
    assert main(argv("compensate", templates / "targets", tmp_path / "joints2.csv")) == 0
    assert main(argv("simulate", templates / "bar", tmp_path / "sim")) == 0
    capsys.readouterr()


# ----------------------------------------------------------------------------- output paths


def test_out_that_is_a_file_is_refused_and_left_alone(templates, tmp_path, capsys):
    folder = Path(shutil.copytree(templates / "bar", tmp_path / "bar"))
    existing = tmp_path / "notes.txt"
    existing.write_text("keep me\n")
    for verb_argv in (["calibrate", str(folder / "dataset.yaml"), "--out", str(existing)],
                      ["simulate", "--example", "industrial_6r", "--kind", "cross_bar",
                       "--rows", "2", "--out", str(existing)],
                      ["calibrate", str(folder / "dataset.yaml"), "--out",
                       str(existing / "inside")]):
        assert main(verb_argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "--out" in err and "notes.txt" in err, err
        assert existing.read_text() == "keep me\n"


def test_out_that_is_a_folder_is_refused_for_a_table(templates, tmp_path, capsys):
    folder = Path(shutil.copytree(templates / "bar", tmp_path / "bar"))
    (tmp_path / "poses").mkdir()
    assert main(argv("fk", folder, tmp_path / "poses")) == 2
    err = capsys.readouterr().err.strip()
    assert "--out" in err and "folder" in err
    assert list((tmp_path / "poses").iterdir()) == []


def test_out_folder_holding_the_inputs_is_refused(templates, tmp_path, capsys):
    """Replacing the output folder as a whole would delete the measurements."""
    folder = Path(shutil.copytree(templates / "bar", tmp_path / "bar"))
    before = sorted(p.name for p in folder.iterdir())
    assert main(["calibrate", str(folder / "dataset.yaml"), "--out", str(folder)]) == 2
    err = capsys.readouterr().err.strip()
    assert "--out" in err and "holds the input" in err
    assert sorted(p.name for p in folder.iterdir()) == before


def test_plan_count_beyond_reason_is_refused_at_once(templates, tmp_path, capsys):
    out = tmp_path / "plan.csv"
    assert main(["plan", str(templates / "tracker" / "dataset.yaml"), "--count", "100000000",
                 "--out", str(out)]) == 2
    assert "--count" in capsys.readouterr().err
    assert not out.exists()


def test_validation_dataset_of_another_robot_is_refused(templates, tmp_path, capsys):
    status = main(["calibrate", str(templates / "bar" / "dataset.yaml"), "--validate",
                   str(templates / "tracker" / "dataset.yaml"), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip()
    assert status == 2 and len(err.splitlines()) == 1
    assert "tracker" in err and "robot" in err
    assert not (tmp_path / "r").exists()


def test_the_same_dataset_fitted_and_held_out_is_refused(templates, tmp_path, capsys):
    dataset = str(templates / "bar" / "dataset.yaml")
    assert main(["calibrate", dataset, "--validate", dataset, "--out", str(tmp_path / "r")]) == 2
    assert "given twice" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("options, fragment", [
    (["--noise", "nan"], "--noise"),
    (["--bar-length", "-400"], "--bar-length"),
    (["--errors", "nan,0.1"], "--errors"),
    (["--errors", "1e300,0.1"], "implausibly large"),
    (["--sockets", "1"], "--sockets"),
    (["--payload", "inf"], "--payload"),
])
def test_bad_simulate_numbers_are_refused(tmp_path, capsys, options, fragment):
    out = tmp_path / "sim"
    status = main(["simulate", "--example", "industrial_6r", "--kind", "cross_bar", "--rows",
                   "2", "--out", str(out), *options])
    err = capsys.readouterr().err.strip()
    assert status == 2 and len(err.splitlines()) == 1 and fragment in err, err
    assert not out.exists()


# ----------------------------------------------------------------------------- tolerated


def test_tolerated_formatting_reads_the_same_numbers(templates, tmp_path):
    """BOM, CRLF, quotes, spaces, blank lines and trailing commas change nothing."""
    clean = load_dataset(templates / "tracker" / "dataset.yaml")
    folder = Path(shutil.copytree(templates / "tracker", tmp_path / "messy"))
    lines = (folder / "points.csv").read_text().splitlines()
    messy = ["\ufeff" + lines[0] + ","]
    for k, line in enumerate(lines[1:]):
        cells = [f' "{c}" ' if i % 2 else f" {c} " for i, c in enumerate(line.split(","))]
        messy.append(",".join(cells) + ",")
        if k % 2:
            messy.append("")
    (folder / "points.csv").write_bytes(("\r\n".join(messy) + "\r\n").encode())
    read = load_dataset(folder / "dataset.yaml")
    np.testing.assert_array_equal(read.joints, clean.joints)
    np.testing.assert_array_equal(read.measured, clean.measured)
    assert set(read.extras) == set(clean.extras)


def test_line_numbers_count_blank_lines(templates, tmp_path, capsys):
    """A message points at the file's own line even after blank lines."""
    folder = Path(shutil.copytree(templates / "tracker", tmp_path / "gaps"))
    lines = (folder / "points.csv").read_text().splitlines()
    lines = [lines[0], "", lines[1], "", "", lines[2]] + lines[3:]
    cells = lines[5].split(",")
    cells[0] = "abc"
    lines[5] = ",".join(cells)  # file line 6
    (folder / "points.csv").write_text("\n".join(lines) + "\n")
    assert main(["calibrate", str(folder / "dataset.yaml"), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "line 6" in err and "'q1'" in err and "'abc'" in err


def test_null_optional_keys_count_as_absent(templates, tmp_path):
    """``laser:`` or ``instrument:`` written with no value is the same as leaving it out."""
    folder = Path(shutil.copytree(templates / "tracker", tmp_path / "t"))
    yaml_set("dataset.yaml", ("instrument",), None)(folder)
    assert load_dataset(folder / "dataset.yaml").instrument is None
    folder = Path(shutil.copytree(templates / "sphere", tmp_path / "s"))
    yaml_set("dataset.yaml", ("laser",), None)(folder)
    loaded = load_dataset(folder / "dataset.yaml")
    assert loaded.origin_guess is None and loaded.direction_guess is None


def test_a_bad_command_line_is_one_line_too(capsys):
    for bad in (["fk"], ["calibrate", "d.yaml", "--out", "r", "--method", "newton"],
                ["plan", "d.yaml", "--count", "many", "--out", "p.csv"]):
        with pytest.raises(SystemExit) as stop:
            main(bad)
        assert stop.value.code == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and err.startswith(f"robocal {bad[0]}: error: "), err
        assert "--help" in err


# --------------------------------------------------------------------- outputs never destroy


def _one_line(capsys, *fragments) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for fragment in fragments:
        assert fragment in err, f"{fragment!r} not in {err!r}"
    return err


@pytest.mark.parametrize("verb", ["fk", "track", "compensate", "plan"])
def test_out_on_a_named_pipe_is_refused_and_left_a_pipe(templates, tmp_path, capsys, verb):
    """Replacing a device or a pipe with a regular file would destroy it (think of
    --out /dev/null run as root)."""
    template = {"fk": "bar", "track": "job", "compensate": "targets", "plan": "tracker"}[verb]
    folder = Path(shutil.copytree(templates / template, tmp_path / template))
    pipe = tmp_path / "pipe.csv"
    os.mkfifo(pipe)
    assert main(argv(verb, folder, pipe)) == 2
    _one_line(capsys, "--out", "pipe.csv", "named pipe")
    assert stat.S_ISFIFO(pipe.lstat().st_mode)


def test_out_on_a_device_is_refused(templates, tmp_path, capsys):
    """/dev/null is only looked at: the check refuses before anything is written."""
    folder = Path(shutil.copytree(templates / "bar", tmp_path / "bar"))
    assert main(argv("fk", folder, Path("/dev/null"))) == 2
    _one_line(capsys, "--out", "/dev/null", "device")
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def _snapshot(folder: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.mark.parametrize("verb, target", [
    ("fk", "touches.csv"), ("fk", "robot.yaml"),
    ("track", "observations.csv"), ("track", "job.yaml"), ("track", "robot.yaml"),
    ("compensate", "targets.csv"), ("compensate", "robot.yaml"),
    ("plan", "dataset.yaml"), ("plan", "robot.yaml"), ("plan", "points.csv"),
])
def test_a_verb_never_writes_over_its_own_input(templates, tmp_path, capsys, verb, target):
    template = {"fk": "bar", "track": "job", "compensate": "targets", "plan": "tracker"}[verb]
    folder = Path(shutil.copytree(templates / template, tmp_path / template))
    before = _snapshot(folder)
    assert main(argv(verb, folder, folder / target)) == 2
    _one_line(capsys, "--out", target)
    assert _snapshot(folder) == before


def test_an_input_reached_through_a_hard_link_is_not_overwritten(templates, tmp_path, capsys):
    folder = Path(shutil.copytree(templates / "bar", tmp_path / "bar"))
    os.link(folder / "touches.csv", tmp_path / "alias.csv")
    before = (folder / "touches.csv").read_bytes()
    assert main(argv("fk", folder, tmp_path / "alias.csv")) == 2
    _one_line(capsys, "--out", "is the input")
    assert (folder / "touches.csv").read_bytes() == before


def test_plan_may_replace_its_own_unmeasured_plan_but_not_measurements(templates, tmp_path,
                                                                       capsys):
    folder = Path(shutil.copytree(templates / "tracker", tmp_path / "tracker"))
    measured = (folder / "points.csv").read_bytes()
    assert main(argv("plan", folder, folder / "points.csv")) == 2
    _one_line(capsys, "--out", "holds readings")
    assert (folder / "points.csv").read_bytes() == measured
    # A plan written there first (its measured columns empty) may be planned again.
    (folder / "points.csv").unlink()
    plan = ["plan", str(folder / "dataset.yaml"), "--count", "12", "--no-refine", "--out",
            str(folder / "points.csv")]
    assert main(plan) == 0, capsys.readouterr().err
    first = (folder / "points.csv").read_text()
    assert first.splitlines()[1].endswith(",,,")
    assert main([*plan, "--seed", "3"]) == 0
    assert (folder / "points.csv").read_text() != first
    capsys.readouterr()


@pytest.mark.parametrize("verb", ["calibrate", "simulate"])
def test_a_folder_robocal_did_not_write_is_refused_unless_forced(templates, tmp_path, capsys,
                                                                 verb):
    folder = tmp_path / "bar"
    simulate(ROBOTS["industrial_6r"](), "cross_bar", rows=12, seed=2, out_dir=folder,
             progress=False)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work\n")
    assert main(argv(verb, folder, mine)) == 2
    _one_line(capsys, "--out", "did not write", "--force")
    assert (mine / "thesis.tex").read_text() == "years of work\n"
    assert main([*argv(verb, folder, mine), "--force"]) == 0
    assert not (mine / "thesis.tex").exists()
    # A folder robocal wrote is replaced without asking.
    assert main(argv(verb, folder, mine)) == 0
    assert main(argv(verb, folder, tmp_path / "new")) == 0  # and a new one is made
    (tmp_path / "empty").mkdir()
    assert main(argv(verb, folder, tmp_path / "empty")) == 0  # an empty one is taken
    capsys.readouterr()


@pytest.mark.parametrize("out", [".", "..", "./", ""])
def test_out_the_current_folder_is_one_line(templates, tmp_path, capsys, monkeypatch, out):
    folder = Path(shutil.copytree(templates / "bar", tmp_path / "bar"))
    work = tmp_path / "work" / "here"
    work.mkdir(parents=True)
    (work / "keep.txt").write_text("keep\n")
    monkeypatch.chdir(work)
    for verb in ("simulate", "calibrate"):
        assert main([*argv(verb, folder, Path("x")), "--out", out, "--force"]) == 2
        _one_line(capsys, "--out")
    assert sorted(p.name for p in work.iterdir()) == ["keep.txt"]
    assert sorted(p.name for p in work.parent.iterdir()) == ["here"]


def _read_only_folder(tmp_path: Path) -> Path:
    """A folder this process cannot write in: chmod'ed for a normal user; as root (who
    ignores permissions) a read-only system folder, or skip."""
    if os.geteuid() != 0:
        folder = tmp_path / "locked"
        folder.mkdir()
        folder.chmod(0o555)
        return folder
    for candidate in (Path("/proc/sys"), Path("/sys")):
        if candidate.is_dir() and not os.access(candidate, os.W_OK):
            return candidate
    pytest.skip("no folder that root cannot write")


def test_a_read_only_output_folder_is_found_before_the_work(templates, tmp_path, capsys,
                                                           monkeypatch):
    from robocal_casadi.commands import calibrate as calibrate_verb

    def no_work(*args, **kwargs):
        raise AssertionError("the calibration ran although its output cannot be written")

    monkeypatch.setattr(calibrate_verb, "run_job", no_work)
    locked = _read_only_folder(tmp_path)
    folder = Path(shutil.copytree(templates / "bar", tmp_path / "bar"))
    assert main(argv("calibrate", folder, locked / "robocal-result")) == 2
    _one_line(capsys, "--out", "not writable")
    assert main(argv("fk", folder, locked / "robocal-poses.csv")) == 2
    _one_line(capsys, "--out", "not writable")


def test_a_folder_that_refuses_new_entries_is_found_before_the_work(templates, tmp_path,
                                                                   capsys, monkeypatch):
    """/proc passes a permission check (root may write anywhere, and its bits say so) yet
    takes no new entry: the output is refused at once, not after the calibration."""
    from robocal_casadi.commands import calibrate as calibrate_verb

    if not (Path("/proc").is_dir() and os.access("/proc", os.W_OK)):
        pytest.skip("no /proc that a permission check passes")

    def no_work(*args, **kwargs):
        raise AssertionError("the calibration ran although its output cannot be written")

    monkeypatch.setattr(calibrate_verb, "run_job", no_work)
    folder = Path(shutil.copytree(templates / "bar", tmp_path / "bar"))
    assert main(argv("calibrate", folder, Path("/proc/robocal-result"))) == 2
    _one_line(capsys, "--out", "not writable")
    assert main(argv("fk", folder, Path("/proc/robocal-poses.csv"))) == 2
    _one_line(capsys, "--out", "not writable")
    assert not [p for p in tmp_path.rglob("*") if "probe" in p.name]


def test_leftovers_of_killed_runs_are_removed_and_live_ones_kept(templates, tmp_path, capsys):
    """A run killed mid-way leaves its staging file or folder; the next run beside it
    removes those whose process is gone, and keeps those of a live run."""
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    folder = Path(shutil.copytree(templates / "bar", tmp_path / "bar"))
    out = tmp_path / "out"
    out.mkdir()
    dead_folder = out / f".sim.robocal-{gone.pid}-abc123"
    dead_folder.mkdir()
    (dead_folder / "points.csv").write_text("half written")
    dead_file = out / f".poses.csv.robocal-{gone.pid}-def456"
    dead_file.write_text("half")
    live = out / f".sim.robocal-{os.getppid()}-ghi789"
    live.mkdir()
    assert main(argv("simulate", folder, out / "sim")) == 0
    assert main(argv("fk", folder, out / "poses.csv")) == 0
    capsys.readouterr()
    assert not dead_folder.exists() and not dead_file.exists()
    assert live.is_dir()
    assert sorted(p.name for p in out.iterdir()) == sorted(["sim", "poses.csv", live.name])


# ----------------------------------------------------------------------------- arguments


def test_every_validate_file_is_kept():
    """One file per --validate; a file after it is a dataset to fit, wherever it stands."""
    from robocal_casadi.cli import build_parser

    parser = build_parser()
    for line in (["--validate", "a.yaml", "--validate", "b.yaml", "fit.yaml"],
                 ["fit.yaml", "--validate", "a.yaml", "--validate", "b.yaml"],
                 ["--validate", "a.yaml", "fit.yaml", "--validate", "b.yaml"]):
        args = parser.parse_args(["calibrate", *line, "--out", "r"])
        assert [p.name for p in args.validate] == ["a.yaml", "b.yaml"], line
        assert [p.name for p in args.datasets] == ["fit.yaml"], line
    assert parser.parse_args(["calibrate", "fit.yaml", "--out", "r"]).validate == []


def test_repeated_validate_reaches_the_calibration(templates, tmp_path, capsys, monkeypatch):
    from robocal_casadi.commands import calibrate as calibrate_verb

    seen = {}

    def record(datasets, validation, *args, **kwargs):
        seen["validation"] = [d.path.name for d in validation]
        raise calibrate_verb.InputError("stop here")

    monkeypatch.setattr(calibrate_verb, "run_job", record)
    names = []
    for k in range(3):
        copy = Path(shutil.copytree(templates / "tracker", tmp_path / f"v{k}"))
        names.append(copy / f"held_out_{k}.yaml")
        (copy / "dataset.yaml").rename(names[-1])
    assert main(["calibrate", str(templates / "tracker" / "dataset.yaml"), "--validate",
                 str(names[0]), "--validate", str(names[1]), "--validate", str(names[2]),
                 "--out", str(tmp_path / "r")]) == 2
    capsys.readouterr()
    assert seen["validation"] == ["held_out_0.yaml", "held_out_1.yaml", "held_out_2.yaml"]


@pytest.mark.parametrize("verb_line", [
    ["simulate", "--example", "industrial_6r", "--kind", "cross_bar", "--out", "x"],
    ["plan", "d.yaml", "--count", "3", "--out", "p.csv"],
    ["compensate", "r.yaml", "t.csv", "--out", "j.csv"],
])
@pytest.mark.parametrize("seed", ["-1", "4294967296", "1e3", "9" * 5000])
def test_a_bad_seed_is_one_line(capsys, verb_line, seed):
    with pytest.raises(SystemExit) as stop:
        main([*verb_line, "--seed", seed])
    assert stop.value.code == 2
    _one_line(capsys, "--seed")


# ---------------------------------------------------------------- YAML and data references


def test_merge_keys_are_read_as_yaml_defines_them(templates, tmp_path):
    """``<<: *name`` copies a mapping's keys, and keys written beside it win: the same
    robot as the one written out in full."""
    folder = Path(shutil.copytree(templates / "bar", tmp_path / "bar"))
    content = yaml.safe_load((folder / "robot.yaml").read_text())
    first, second = content["joints"][:2]
    others = yaml.safe_dump({k: v for k, v in content.items() if k != "joints"})
    rest = [yaml.safe_dump(j, default_flow_style=True).strip() for j in content["joints"][2:]]
    merged = others + "joints:\n" + "\n".join(
        [f"- &first {yaml.safe_dump(first, default_flow_style=True).strip()}",
         f"- {{<<: *first, theta: {second['theta']!r}, d: 123.5}}"] + [f"- {j}" for j in rest])
    (folder / "robot.yaml").write_text(merged + "\n")
    explicit = dict(first, theta=second["theta"], d=123.5)
    content["joints"][1] = explicit
    (folder / "explicit.yaml").write_text(yaml.safe_dump(content))
    from robocal_casadi.model.robot import load_robot

    assert load_robot(folder / "robot.yaml") == load_robot(folder / "explicit.yaml").with_units(
        load_robot(folder / "robot.yaml").units)
    assert load_robot(folder / "robot.yaml").joints[1].d == pytest.approx(0.1235)
    # A key written twice beside the merge is still a duplicate.
    (folder / "robot.yaml").write_text(merged.replace("d: 123.5}", "d: 123.5, d: 1}") + "\n")
    with pytest.raises(Exception, match="duplicate key 'd'"):
        load_robot(folder / "robot.yaml")


def test_a_data_table_outside_the_folder_needs_the_option(templates, tmp_path, capsys):
    """``data: ../x.csv`` reads only with --allow-outside-data; what is echoed of a
    foreign file is cut short."""
    folder = Path(shutil.copytree(templates / "tracker", tmp_path / "sets" / "tracker"))
    (folder / "points.csv").rename(tmp_path / "points.csv")
    replace("dataset.yaml", "data: points.csv", "data: ../../points.csv")(folder)
    with pytest.raises(Exception, match="outside"):
        load_dataset(folder / "dataset.yaml")
    moved = load_dataset(folder / "dataset.yaml", allow_outside_data=True)
    assert moved.rows == 6
    # A foreign file: a long first line is not echoed whole.
    (tmp_path / "foreign.txt").write_text("secret:" + "s" * 5000 + "\n1\n")
    replace("dataset.yaml", "data: ../../points.csv", "data: ../../foreign.txt")(folder)
    out = tmp_path / "r"
    assert main(["calibrate", str(folder / "dataset.yaml"), "--out", str(out),
                 "--allow-outside-data"]) == 2
    err = _one_line(capsys, "foreign.txt")
    assert len(err) < 600 and "s" * 300 not in err, err
    assert not out.exists()


def test_inputs_are_checked_before_reading_so_nothing_hangs(templates, tmp_path):
    """A named pipe as an input would block a reader forever: the CLI, run as a separate
    process, must refuse it at once."""
    folder = Path(shutil.copytree(templates / "bar", tmp_path / "bar"))
    os.mkfifo(tmp_path / "joints.csv")
    done = subprocess.run([sys.executable, "-m", "robocal_casadi.cli", "fk",
                           str(folder / "robot.yaml"), str(tmp_path / "joints.csv"), "--out",
                           str(tmp_path / "poses.csv")], capture_output=True, text=True,
                          timeout=120, env={**os.environ, "PYTHONPATH": str(REPOSITORY)})
    assert done.returncode == 2, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "pipe" in done.stderr
