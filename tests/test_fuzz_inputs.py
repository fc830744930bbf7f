"""Generated broken inputs, outputs and API calls: every one ends cleanly.

Valid files come from the simulator (each kind of dataset, a 6R in mm/deg) and the
shipped UR10 series (mm/rad). A seeded generator breaks one of them at a time:
truncation, a deleted or doubled line, a value replaced by text of the wrong type, NaN,
infinity, a huge number, an unknown or missing key, a changed unit, an empty file,
random bytes, a folder in place of the file. Loading the result must either succeed
with finite numbers, or raise ``InputError`` whose message is one short line naming a
file of the dataset (or, for API calls, the argument). Nothing else may escape: no
``TypeError``, ``KeyError`` or traceback. The command line gets the same files
through ``fk`` and ``calibrate`` in-process (exit status 2, one line on standard error,
no output left), and a set of outputs that cannot be written.

The default run draws ``CASES`` file cases (a few hundred, well under a minute); the
``slow`` test draws ten times as many with other seeds.
"""

from __future__ import annotations

import random
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from robocal_casadi import calibrate, compensate, load_dataset, load_robot, simulate
from robocal_casadi.cli import MAX_MESSAGE, main
from robocal_casadi.common.table import read_table
from robocal_casadi.errors import InputError
from robocal_casadi.model.examples import ROBOTS

REPOSITORY = Path(__file__).resolve().parents[1]
UR10 = REPOSITORY / "robocal_casadi" / "data" / "ur10-ipa"
CASES = 320  # generated file cases in the default run
LONGEST = MAX_MESSAGE + 60  # characters of an error line, with the verb's prefix

# Values a person or a broken tool could leave in a field (text of a YAML scalar or a
# CSV cell): wrong types, non-finite and huge numbers, YAML syntax and tags.
GARBAGE = ["", "nan", ".nan", ".inf", "-.inf", "inf", "-1e400", "1e308", "1e-320", "abc",
           "[1, 2", "{", "}", "~", "null", "0x1F", "1_000", "true", "[]", "{}", "[[]]",
           "'text'", '"', "- a\n- b", "!!python/object/apply:os.system ['true']",
           "&a [*a]", "*undefined", "x" * 5000, "１２", "12,5", "−3", "1e", "--1", "0",
           "-0", "999999999999999999999999999", "\t", "%YAML 9.9", "? complex", "|",
           ">-\n  folded", "2001-12-14", "=", "null: null", "<<: 5"]


# ----------------------------------------------------------------------------- templates


@pytest.fixture(scope="module")
def templates(tmp_path_factory) -> dict[str, Path]:
    """Valid dataset folders by name: their dataset file, robot file and table."""
    root = tmp_path_factory.mktemp("fuzz-valid")
    robot = ROBOTS["ur_type"]()
    made = {
        "tracker": simulate(robot, "tracker_points", rows=8, seed=2, out_dir=root / "tracker",
                            progress=False),
        "bar": simulate(robot, "cross_bar", rows=2, seed=2, out_dir=root / "bar",
                        progress=False),
        "artifact": simulate(robot, "artifact_touches", rows=2, sockets=3, touches=2, seed=2,
                             out_dir=root / "artifact", progress=False),
        "sphere": simulate(robot, "sphere_laser", rows=6, seed=2, out_dir=root / "sphere",
                           progress=False),
    }
    folders = {name: sim.dataset_path for name, sim in made.items()}
    shipped = root / "ur10"
    shutil.copytree(UR10, shipped)
    folders["ur10"] = shipped / "series_D_fit.yaml"
    return folders


def _copy(dataset: Path, into: Path) -> Path:
    """A private copy of the folder of ``dataset``; returns the copied dataset file."""
    shutil.copytree(dataset.parent, into)
    return into / dataset.name


def _inputs(dataset: Path) -> dict[str, Path]:
    """The dataset's own files: the dataset, its robot and its table."""
    folder = dataset.parent
    table = next(p for p in folder.glob("*.csv") if p.stem in dataset.read_text())
    return {"dataset": dataset, "robot": folder / "robot.yaml", "table": table}


# ----------------------------------------------------------------------------- mutations


def _lines(text: str) -> list[str]:
    return text.splitlines(keepends=True)


def _scalar_positions(text: str) -> list[tuple[int, int]]:
    """(start, end) of each value after ``key:`` or in a flow list ``[...]`` on a line."""
    spans = []
    offset = 0
    for line in _lines(text):
        colon = line.find(": ")
        if colon >= 0:
            start = offset + colon + 2
            spans.append((start, offset + len(line.rstrip("\n"))))
        offset += len(line)
    return spans


def mutate(kind: str, text: str, rng: random.Random) -> str | bytes:
    """One generated break of ``text`` (a YAML file or a CSV table)."""
    lines = _lines(text)
    choice = rng.randrange(12)
    if choice == 0:  # truncated anywhere
        return text[:rng.randrange(len(text))]
    if choice == 1 and len(lines) > 1:  # a line deleted
        del lines[rng.randrange(len(lines))]
        return "".join(lines)
    if choice == 2:  # a line doubled
        k = rng.randrange(len(lines))
        lines.insert(k, lines[k])
        return "".join(lines)
    if choice == 3:  # random bytes somewhere
        at = rng.randrange(len(text) + 1)
        noise = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 12)))
        data = text.encode()
        return data[:at] + noise + data[at:]
    if choice == 4:  # empty, or only blanks
        return rng.choice(["", "\n\n", "   ", "\ufeff"])
    if kind == "table":
        return _mutate_table(lines, rng)
    return _mutate_yaml(text, lines, rng)


def _mutate_table(lines: list[str], rng: random.Random) -> str:
    header = lines[0].rstrip("\n").split(",")
    rows = [line.rstrip("\n").split(",") for line in lines[1:] if line.strip()]
    pick = rng.randrange(6)
    if pick == 0 and rows:  # one cell replaced by garbage
        row = rng.choice(rows)
        row[rng.randrange(len(row))] = rng.choice(GARBAGE).replace("\n", " ")
    elif pick == 1:  # a column renamed, dropped or added
        k = rng.randrange(len(header))
        action = rng.randrange(3)
        if action == 0:
            header[k] = rng.choice(["", header[k].upper(), header[k] + " ", "q99", header[0]])
        elif action == 1:
            header.pop(k)
            for row in rows:
                if k < len(row):
                    row.pop(k)
        else:
            header.append(rng.choice(["extra", "", "temperature", "q7"]))
            for row in rows:
                row.append(rng.choice(GARBAGE[:12]).replace("\n", " "))
    elif pick == 2 and rows:  # a row cut short or made long
        row = rng.choice(rows)
        if rng.random() < 0.5 and len(row) > 1:
            row.pop()
        else:
            row.append("1")
    elif pick == 3:  # another separator
        sep = rng.choice([";", "\t", "|", " "])
        return "\n".join(sep.join(r) for r in [header] + rows) + "\n"
    elif pick == 4 and rows:  # a huge or tiny number
        row = rng.choice(rows)
        row[rng.randrange(len(row))] = rng.choice(["1e300", "-1e300", "1e-300", "4e9", "-7e5"])
    else:  # the header only
        rows = []
    return "\n".join(",".join(r) for r in [header] + rows) + "\n"


def _mutate_yaml(text: str, lines: list[str], rng: random.Random) -> str:
    spans = _scalar_positions(text)
    pick = rng.randrange(5)
    if pick == 0 and spans:  # a value replaced by garbage
        start, end = rng.choice(spans)
        return text[:start] + rng.choice(GARBAGE) + text[end:]
    if pick == 1:  # an unknown key, at the top or indented
        k = rng.randrange(len(lines) + 1)
        lines.insert(k, rng.choice(["bogus_key: 1\n", "  bogus_key: 1\n", "Kind: x\n",
                                    "units: {length: furlong, angle: deg}\n"]))
        return "".join(lines)
    if pick == 2:  # a key's line removed (a required key missing)
        keyed = [i for i, line in enumerate(lines) if ":" in line]
        if keyed:
            del lines[rng.choice(keyed)]
        return "".join(lines)
    if pick == 3:  # units changed
        return text.replace(rng.choice(["mm", "deg", "rad", "m\n"]),
                            rng.choice(["MM", "inch", "", "degrees", "m", "rad", "deg"]), 1)
    # the whole file one value of the wrong type
    return rng.choice(["- 1\n- 2\n", "42\n", "'just text'\n", "null\n", "[\n", "{a: [}\n"])


# ----------------------------------------------------------------------------- judging


def _judge_load(dataset: Path, inputs: dict[str, Path]) -> str:
    """Load ``dataset``: 'ok' (finite data) or 'refused' (a proper ``InputError``)."""
    try:
        loaded = load_dataset(dataset, allow_outside_data=False)
    except InputError as error:
        message = str(error)
        assert "\n" not in message.strip() or message.count("\n") == 0, message
        assert len(" ".join(message.split())) <= LONGEST, message[:300]
        named = error.file is not None and Path(error.file).name in {
            p.name for p in inputs.values()}
        assert named, f"names no input file: {message[:300]}"
        return "refused"
    for name in ("joints", "measured", "distance"):
        value = getattr(loaded, name, None)
        if value is not None:
            assert np.all(np.isfinite(value)), name
    return "ok"


def _file_case(templates: dict[str, Path], tmp_path: Path, seed: int) -> str:
    rng = random.Random(seed)
    name = rng.choice(sorted(templates))
    dataset = _copy(templates[name], tmp_path / f"case{seed}")
    inputs = _inputs(dataset)
    role = rng.choice(["dataset", "robot", "table", "dataset", "table"])
    target = inputs[role]
    if rng.random() < 0.04:  # a folder, or nothing, in place of the file
        target.unlink()
        if rng.random() < 0.5:
            target.mkdir()
    else:
        broken = mutate("table" if role == "table" else "yaml", target.read_text(), rng)
        if isinstance(broken, bytes):
            target.write_bytes(broken)
        else:
            target.write_text(broken)
    return _judge_load(dataset, inputs)


def test_generated_broken_files_load_or_are_refused_cleanly(templates, tmp_path):
    outcomes = [_file_case(templates, tmp_path, seed) for seed in range(CASES)]
    refused = outcomes.count("refused")
    # most breaks must be found: a generator that breaks nothing would test nothing
    assert refused >= 0.6 * CASES, outcomes.count("ok")


@pytest.mark.slow
def test_many_more_generated_broken_files(templates, tmp_path):
    for seed in range(10_000, 10_000 + 10 * CASES):
        _file_case(templates, tmp_path, seed)
        shutil.rmtree(tmp_path / f"case{seed}")


# ----------------------------------------------------------------------------- command line


def _one_error_line(capsys, verb: str) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert "Traceback" not in captured.err, captured.err[-2000:]
    assert len(lines) == 1 and lines[0].startswith(f"robocal {verb}: error: "), captured.err
    assert len(lines[0]) <= LONGEST
    return lines[0]


@pytest.mark.parametrize("seed", range(24))
def test_fk_on_broken_robot_and_joint_files(templates, tmp_path, capsys, seed):
    rng = random.Random(500 + seed)
    folder = tmp_path / "fk"
    folder.mkdir()
    shutil.copy(templates["tracker"].parent / "robot.yaml", folder / "robot.yaml")
    table = read_table(templates["tracker"].parent / "points.csv")
    joints = [c for c in table.columns if c.startswith("q")]
    (folder / "joints.csv").write_text(
        ",".join(joints) + "\n" + "\n".join(",".join(r) for r in zip(
            *[table.text(c) for c in joints])) + "\n")
    target = folder / ("robot.yaml" if seed % 2 else "joints.csv")
    broken = mutate("yaml" if seed % 2 else "table", target.read_text(), rng)
    if isinstance(broken, bytes):
        target.write_bytes(broken)
    else:
        target.write_text(broken)
    out = tmp_path / "poses.csv"
    status = main(["fk", str(folder / "robot.yaml"), str(folder / "joints.csv"),
                   "--out", str(out)])
    if status == 0:
        assert out.is_file()
        capsys.readouterr()
        return
    line = _one_error_line(capsys, "fk")
    assert status == 2 and ("robot.yaml" in line or "joints.csv" in line), line
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == ["fk"]


def _first_cell(table: Path, value: str) -> None:
    """Replace the first cell of the first data row of ``table`` by ``value``."""
    header, first, *rest = table.read_text().splitlines()
    cells = first.split(",")
    cells[0] = value
    table.write_text("\n".join([header, ",".join(cells), *rest]) + "\n")


BREAKS_FOR_CALIBRATE: dict[str, Callable[[dict[str, Path]], None]] = {
    "dataset empty": lambda f: f["dataset"].write_text(""),
    "dataset a list": lambda f: f["dataset"].write_text("- 1\n- 2\n"),
    "dataset a folder": lambda f: (f["dataset"].unlink(), f["dataset"].mkdir()),
    "robot missing": lambda f: f["robot"].unlink(),
    "robot empty": lambda f: f["robot"].write_text(""),
    "robot random bytes": lambda f: f["robot"].write_bytes(bytes(range(256)) * 4),
    "table empty": lambda f: f["table"].write_text(""),
    "table header only": lambda f: f["table"].write_text(
        f["table"].read_text().splitlines()[0] + "\n"),
    "table a folder": lambda f: (f["table"].unlink(), f["table"].mkdir()),
    "table truncated mid-row": lambda f: f["table"].write_text(
        f["table"].read_text()[:-9]),
    "table NaN": lambda f: _first_cell(f["table"], "nan"),
    "table infinity": lambda f: _first_cell(f["table"], "-inf"),
    "table huge": lambda f: _first_cell(f["table"], "1e300"),
    "units unknown": lambda f: f["dataset"].write_text(
        f["dataset"].read_text().replace("mm", "furlong", 1)),
    "unknown key": lambda f: f["dataset"].write_text(f["dataset"].read_text() + "colour: 1\n"),
    "kind missing": lambda f: f["dataset"].write_text(
        "".join(line for line in _lines(f["dataset"].read_text())
                if not line.startswith("kind:"))),
}


@pytest.mark.parametrize("kind", ["tracker", "bar", "sphere"])
@pytest.mark.parametrize("case", sorted(BREAKS_FOR_CALIBRATE))
def test_calibrate_on_broken_files(templates, tmp_path, capsys, kind, case):
    dataset = _copy(templates[kind], tmp_path / "data")
    inputs = _inputs(dataset)
    BREAKS_FOR_CALIBRATE[case](inputs)
    out = tmp_path / "out"
    status = main(["calibrate", str(dataset), "--out", str(out)])
    line = _one_error_line(capsys, "calibrate")
    assert status == 2
    assert any(p.name in line for p in inputs.values()), line
    assert not out.exists()


# ----------------------------------------------------------------------------- outputs


def _outputs(folder: Path, inputs: dict[str, Path]) -> dict[str, Path]:
    blocker = folder / "a-file"
    blocker.write_text("mine\n")
    return {"the dataset file": inputs["dataset"], "the table": inputs["table"],
            "the robot file": inputs["robot"], "the data folder": inputs["dataset"].parent,
            "under a file": blocker / "sub", "an existing file": blocker,
            "a system folder": Path("/proc/robocal-out"), "a device": Path("/dev/null")}


@pytest.mark.parametrize("where", ["the dataset file", "the table", "the robot file",
                                   "the data folder", "under a file", "an existing file",
                                   "a system folder", "a device"])
@pytest.mark.parametrize("verb", ["calibrate", "fk", "simulate"])
def test_outputs_that_cannot_be_written_are_refused(templates, tmp_path, capsys, verb, where):
    dataset = _copy(templates["tracker"], tmp_path / "data")
    inputs = _inputs(dataset)
    before = {p: p.read_bytes() for p in inputs.values()}
    out = _outputs(tmp_path, inputs)[where]
    if verb == "calibrate":
        argv = ["calibrate", str(dataset), "--out", str(out)]
    elif verb == "fk":
        argv = ["fk", str(inputs["robot"]), str(inputs["table"]), "--out", str(out)]
    else:
        argv = ["simulate", "--robot", str(inputs["robot"]), "--kind", "tracker_points",
                "--rows", "4", "--out", str(out)]
    if verb == "fk" and where in ("an existing file",):
        pytest.skip("fk replaces a CSV it is told to write")
    status = main(argv)
    _one_error_line(capsys, verb)
    assert status == 2
    assert {p: p.read_bytes() for p in inputs.values()} == before
    assert (tmp_path / "a-file").read_text() == "mine\n"


# ----------------------------------------------------------------------------- API


WRONG = [None, 3, 2.5, "text", b"bytes", [], {}, {"a": 1}, object(), np.nan, -1, True,
         ["a", None], np.zeros((2, 2))]


def _refused_cleanly(call: Callable[[], object]) -> str:
    try:
        call()
    except InputError as error:  # ArgumentError is one
        message = str(error)
        assert "\n" not in message and len(message) <= LONGEST, message[:300]
        return "refused"
    return "ok"


@pytest.mark.parametrize("value", WRONG, ids=lambda v: type(v).__name__)
def test_load_functions_refuse_wrong_types(value):
    assert _refused_cleanly(lambda: load_dataset(value)) == "refused"
    assert _refused_cleanly(lambda: load_robot(value)) == "refused"
    assert _refused_cleanly(lambda: load_dataset(UR10 / "series_D_fit.yaml",
                                                 robot=value)) in ("refused", "ok")


def _valid_for(argument: str, value) -> bool:
    """The few ``WRONG`` values a calibrate argument accepts: an empty list for none,
    None for no selection or all parameters, numbers where numbers are due."""
    if isinstance(value, list) and not value and argument in ("validation", "effects"):
        return True
    if value is None and argument in ("select_growth", "parameters"):
        return True
    plain_number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if argument == "select_growth" and plain_number and value >= 0:
        return True
    return argument == "max_iterations" and plain_number and value >= 1 and value == int(value)


@pytest.mark.parametrize("argument", ["datasets", "validation", "effects", "method", "loss",
                                      "max_iterations", "select_growth", "rule",
                                      "parameters"])
def test_calibrate_refuses_wrong_argument_types(argument):
    dataset = load_dataset(UR10 / "series_D_fit.yaml")
    for value in WRONG:
        if _valid_for(argument, value):
            continue
        kwargs = {argument: value}
        datasets = value if argument == "datasets" else [dataset]
        kwargs.pop("datasets", None)
        outcome = _refused_cleanly(lambda d=datasets, k=kwargs: calibrate(d, **k))
        assert outcome == "refused", (argument, value)


@pytest.mark.parametrize("value", WRONG + [[[np.nan, 0, 0]], [[1e400, 0, 0]], [[0, 0]],
                                           np.zeros((0, 3))],
                         ids=lambda v: type(v).__name__)
def test_compensate_refuses_wrong_targets(value):
    robot = load_robot(UR10 / "robot.yaml")
    assert _refused_cleanly(lambda: compensate(robot, value)) == "refused"
    assert _refused_cleanly(lambda: compensate(value, [[0.5, 0.2, 0.4]])) == "refused"


@pytest.mark.parametrize("argument, value", [
    ("kind", "laser"), ("kind", None), ("rows", 0), ("rows", 10**12), ("rows", "5"),
    ("rows", 2.5), ("noise", -1.0), ("noise", np.nan), ("noise", "x"), ("sockets", 1),
    ("touches", 0), ("readings", "poses"), ("robot", None), ("robot", 5),
])
def test_simulate_refuses_wrong_arguments(tmp_path, argument, value):
    kwargs = dict(robot=ROBOTS["ur_type"](), kind="tracker_points", rows=4,
                  out_dir=tmp_path / "s", progress=False)
    kwargs[argument] = value
    robot = kwargs.pop("robot")
    kind = kwargs.pop("kind")
    assert _refused_cleanly(lambda: simulate(robot, kind, **kwargs)) == "refused"
    assert not (tmp_path / "s").exists()

