"""A 7-DOF arm with two differential cable pairs: what diagnosis says, with and without the
drive and the transmission declared, against the simulated truth.

The arm is our own (``ARM`` below): seven revolute joints on cables, joints 2-3 and 5-6
each driven by a differential pair of motors. Its true model carries geometric errors,
compliance under gravity with cross terms inside each pair (``coupled_compliance``) and a
lag behind each of the four motors' directions of motion (``motor_play``), of sizes a
cable-driven arm shows. Tracker data (0.015 mm per coordinate, declared with
``instrument_noise``), ``--rows`` readings to fit and ``--held`` held out from another
draw of the same robot (``simulate --truth``), all simulated by ``robocal_casadi.simulate``.

The calibration runs three times in one process on the same tables: with a robot file
that declares neither drive nor transmission (what the terminal says about drives, the
effects named, the held-out RMS), with ``drive: cable`` but no transmission (what the
drive alone allows), and with the robot file the data were simulated with
(``drive: cable`` on every joint and the two groups in ``transmission:``): each effect's
estimates beside the truth with their relative errors, and the held-out RMS beside the
noise floor (the tracker's noise on a 3-D point error, sqrt(3) times 0.015 mm). Prints
JSON; ``--out`` also saves it as ``benchmarks/results/cable.json`` the way
``readme_measured.py --run cable`` does.

    python benchmarks/cable.py [--seed S] [--rows N] [--held M] [--out]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from robocal_casadi.calibration import calibrate
from robocal_casadi.calibration.drive_hints import drive_lines
from robocal_casadi.commands.calibrate import summary
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.instruments.simulate import simulate, simulate_again
from robocal_casadi.model.robot import load_robot, save_robot

NOISE = 1.5e-5  # [m] per tracker coordinate
DEG = math.pi / 180
ERRORS = (2e-4, 2e-4)  # [m, rad] standard deviations of the true geometric errors
# Compliance matrices [rad/Nm] of the two pairs (stiffnesses of a few thousand Nm/rad at
# the shoulder, a few hundred at the wrist) and each motor's lost motion at the joints.
TRUTH = {"coupled_compliance": {(2, 3): (1.5e-4, 5e-5, 2.5e-4), (5, 6): (2e-3, 6e-4, 3e-3)},
         "motor_play": {2: 0.15 * DEG, 3: 0.25 * DEG, 5: 0.3 * DEG, 6: 0.2 * DEG}}
ARM = """\
name: cable-arm-7r
convention: dh
units: {length: mm, angle: deg}
joints:
  - {type: revolute, theta: 0, d: 340, a: 0, alpha: -90, limits: [-150, 150],
     mass: 8.0, com: [0, 60, 10], drive: cable}
  - {type: revolute, theta: 0, d: 0, a: 0, alpha: 90, limits: [-110, 110],
     mass: 3.0, com: [0, 10, 40], drive: cable}
  - {type: revolute, theta: 0, d: 540, a: 45, alpha: -90, limits: [-150, 150],
     mass: 4.5, com: [-20, 0, -180], drive: cable}
  - {type: revolute, theta: 0, d: 0, a: -45, alpha: 90, limits: [-50, 175],
     mass: 2.2, com: [20, 60, 5], drive: cable}
  - {type: revolute, theta: 0, d: 300, a: 0, alpha: -90, limits: [-160, 160],
     mass: 1.4, com: [0, 0, -90], drive: cable}
  - {type: revolute, theta: 0, d: 0, a: 0, alpha: 90, limits: [-90, 90],
     mass: 0.6, com: [0, 15, 10], drive: cable}
  - {type: revolute, theta: 0, d: 70, a: 0, alpha: 0, limits: [-170, 170],
     mass: 0.3, com: [0, 0, 25], drive: cable}
transmission:
  - {joints: [2, 3], motors: [[1, 1], [1, -1]]}
  - {joints: [5, 6], motors: [[1, 1], [1, -1]]}
"""


def _case(root: Path, seed: int, rows: int, held_rows: int):
    """The fit and held-out datasets (declared robot file) and their truth."""
    (root / "arm.yaml").write_text(ARM)
    fit = simulate(root / "arm.yaml", "tracker_points", out_dir=root / "fit", rows=rows,
                   noise=NOISE, seed=seed, geometric_errors=ERRORS, effects=TRUTH,
                   progress=False)
    held = simulate_again(fit.truth_path, out_dir=root / "held", rows=held_rows,
                          seed=seed + 1, progress=False)
    return fit, held


def _undeclared(root: Path, simulated, drive: str = "gear") -> Path:
    """A copy of ``simulated``'s dataset whose robot file declares no transmission and
    ``drive`` on every joint (gear, the default: no drive declared); returns the dataset
    file."""
    folder = root / f"{drive}_{simulated.dataset_path.parent.name}"
    folder.mkdir()
    robot = load_robot(simulated.robot_path)
    robot = replace(robot, transmission=(),
                    joints=tuple(replace(j, drive=drive) for j in robot.joints))
    save_robot(robot, folder / simulated.robot_path.name)
    for path in (simulated.dataset_path, simulated.table_path):
        (folder / path.name).write_bytes(path.read_bytes())
    return folder / simulated.dataset_path.name


def _held_out(result) -> dict:
    floor = NOISE * math.sqrt(3)
    return {"geometric": result.validation.rms_geometric / 1e-3,
            "final": result.validation.rms_final / 1e-3, "noise_floor": floor / 1e-3,
            "final_over_floor": result.validation.rms_final / floor}


def _run_undeclared(fit_path: Path, held_path: Path) -> dict:
    start = time.perf_counter()
    result = calibrate([load_dataset(fit_path)], [load_dataset(held_path)])
    seconds = time.perf_counter() - start
    terminal = summary(result).splitlines()
    return {"effects": [e.summary for e in result.effects],
            "effect_names": [f"{e.name}{list(e.joints)}" for e in result.effects],
            "drive_lines": drive_lines(result),
            "refused_line": next((line for line in terminal if line.startswith("not added")),
                                 None),
            "held_out_rms_mm": _held_out(result),
            "remains": None if result.remainder is None else
            result.remainder.sentence(result.units),
            "seconds": seconds}


def _run_declared(fit, held) -> dict:
    start = time.perf_counter()
    result = calibrate([fit.load()], [held.load()])
    seconds = time.perf_counter() - start
    truth = fit.truth.effects.as_dict()
    estimates = {}
    for name, entry in truth.items():
        found = next((e for e in result.effects if e.name == name), None)
        estimates[name] = {
            parameter: {"true": value,
                        "found": None if found is None else found.parameters.get(parameter),
                        "std": None if found is None else found.std.get(parameter),
                        "relative_error": None if found is None or parameter not in
                        found.parameters else abs(found.parameters[parameter] - value) /
                        abs(value)}
            for parameter, value in entry["parameters"].items()}
    errors = [p["relative_error"] for e in estimates.values() for p in e.values()]
    return {"effects": [e.summary for e in result.effects],
            "effect_names": [f"{e.name}{list(e.joints)}" for e in result.effects],
            "estimates": estimates,
            "largest_relative_error": None if None in errors else max(errors),
            "held_out_rms_mm": _held_out(result),
            "remains": None if result.remainder is None else
            result.remainder.sentence(result.units),
            "seconds": seconds}


def measure(seed: int, rows: int, held_rows: int) -> dict:
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        fit, held = _case(root, seed, rows, held_rows)
        runs = {"undeclared": _run_undeclared(_undeclared(root, fit), _undeclared(root, held)),
                "drive_only": _run_undeclared(_undeclared(root, fit, "cable"),
                                              _undeclared(root, held, "cable")),
                "declared": _run_declared(fit, held)}
    return {"case": f"7-DOF cable arm, differential pairs 2-3 and 5-6, coupled compliance and "
                    f"motor play, tracker {NOISE / 1e-3:g} mm per coordinate (declared), "
                    f"{rows} fit / {held_rows} held out from another draw",
            "targets": {"relative_error": 0.1, "final_over_floor": 1.1}, **runs}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--rows", type=int, default=300)
    parser.add_argument("--held", type=int, default=150)
    parser.add_argument("--out", action="store_true",
                        help="also save the JSON as benchmarks/results/cable.json")
    args = parser.parse_args()
    output = measure(args.seed, args.rows, args.held)
    print(json.dumps(output, indent=1))
    if args.out:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        import readme_measured

        arguments = [a for a in sys.argv[1:] if a != "--out"]
        readme_measured.save("cable", "cable.py", arguments, output)


if __name__ == "__main__":
    main()
