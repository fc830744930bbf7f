"""Arms that are not stiff: what diagnosis names on simulated tracker data, and how close the
held-out error comes to the noise floor.

Scenarios (``robocal_casadi.simulate``; fit and held-out data from the same true robot,
separate tables in measurement order, the held-out placement of the instrument refitted;
for backlash the held-out rows are those measured after the fit rows, in one placement):

* ``cable_arm``: a 7-DOF arm (the Panda-like example) with every joint cable-driven:
  transmission coupling on the differential pairs (joint 3 takes 1.5 % of joint 2's
  motion, joint 6 -1.2 % of joint 5's), cable compliance on joints 2 and 4, hysteresis of
  0.17 deg on joint 1; payload 0 .. 3 kg.
* ``bending_link``: the example 6R industrial arm with its upper arm (link 2) bending under
  a payload of 0 .. 20 kg and its own weight; must be named link deflection (or left
  unexplained), not joint compliance.
* ``sagging_link``: the same arm's tool sagging straight down in proportion to the payload
  times the cosine of the upper arm's elevation (the bending moment of link 2).
* ``backlash``: backlash of 0.034 deg on joints 2 and 3 of the 6R arm, the held-out rows
  measured after the fit rows, in a table of their own.
* ``clean``: geometric errors only; diagnosis must add nothing.

For each: the effects named with their joints and fitted values against the truth, the
RMS [m] of the fit and held-out data against the noise floor (``noise * sqrt(3)``, the
3-D error of the tracker's per-coordinate noise), and seconds. Prints JSON.

    python benchmarks/nonstiff.py [--rows 400] [--only cable_arm,backlash]
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from robocal_casadi.calibration import calibrate
from robocal_casadi.effects.motion import is_derived_column
from robocal_casadi.instruments.datasets import dataset_rows
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import ROBOTS

NOISE = 2e-5  # [m] per coordinate
HELD_OUT_ROWS = 150


def cable_arm():
    nominal = ROBOTS["panda_7dof"]()
    robot = replace(nominal, joints=tuple(replace(j, drive="cable") for j in nominal.joints))
    effects = {"transmission_coupling": {"3@2": 1.5e-2, "6@5": -1.2e-2},
               "joint_compliance": {2: 2e-4, 4: 3e-4}, "hysteresis": {1: 3e-3}}
    return robot, effects, (0.0, 3.0)


def bending_link():
    return ROBOTS["industrial_6r"](), {"link_deflection": {2: (3e-6, 4e-5, 0.0, 0.0)}}, (0.0, 20.0)


def sagging_link():
    return ROBOTS["industrial_6r"](), {"link_deflection": {2: (0.0, 0.0, 2e-6, 0.0)}}, (0.0, 20.0)


def backlash():
    return ROBOTS["industrial_6r"](), {"backlash": {2: 6e-4, 3: 6e-4}}, None


def clean():
    return ROBOTS["industrial_6r"](), {}, (0.0, 20.0)


IN_TIME_ORDER = ("backlash",)  # held out: the rows measured after the fit rows
SCENARIOS = {"cable_arm": cable_arm, "bending_link": bending_link,
             "sagging_link": sagging_link, "backlash": backlash, "clean": clean}


def _later_rows(folder: Path, robot, effects, payload, rows: int, seed: int):
    """One table measured in order, cut into the fit rows and the rows after them, each a
    table of its own (the later one knows nothing of the rows before it)."""
    whole = simulate(robot, "tracker_points", out_dir=folder, rows=rows + HELD_OUT_ROWS,
                     noise=NOISE, seed=seed, effects=effects, geometric_errors=(5e-4, 5e-4),
                     mounted_error=0.0, payload=payload, progress=False)
    data = whole.load()
    first = np.arange(rows + HELD_OUT_ROWS) < rows
    parts = []
    for mask in (first, ~first):
        part = dataset_rows(data, mask)
        parts.append(replace(part, extras={k: v for k, v in part.extras.items()
                                           if not is_derived_column(k)}))
    return whole, parts


def run(name: str, rows: int, folder: Path, seed: int = 31) -> dict:
    robot, effects, payload = SCENARIOS[name]()
    start = time.perf_counter()
    if name in IN_TIME_ORDER:
        fit, (fit_data, held_out_data) = _later_rows(folder / name, robot, effects, payload,
                                                     rows, seed)
    else:
        fit = simulate(robot, "tracker_points", out_dir=folder / name / "fit", rows=rows,
                       noise=NOISE, seed=seed, effects=effects, geometric_errors=(5e-4, 5e-4),
                       mounted_error=0.0, payload=payload, progress=False)
        # the same true robot (geometry and instrument) measured again, another placement
        held_out = simulate(robot, "tracker_points", out_dir=folder / name / "held_out",
                            rows=HELD_OUT_ROWS, noise=NOISE, seed=seed + 1, effects=effects,
                            geometric_errors=dict(fit.truth.parameter_errors),
                            mounted_error=0.0, payload=payload, progress=False)
        fit_data, held_out_data = fit.load(), held_out.load()
    result = calibrate([fit_data], [held_out_data])
    floor = NOISE * math.sqrt(3)
    truth = fit.truth.effects.as_dict()
    return {
        "scenario": name, "rows": rows, "held_out_rows": HELD_OUT_ROWS, "noise_floor_m": floor,
        "truth": {k: {"joints": v["joints"], "parameters": v["parameters"]}
                  for k, v in truth.items()},
        "found": [{"name": e.name, "joints": list(e.joints),
                   "parameters": {k: float(v) for k, v in e.parameters.items()}}
                  for e in result.effects],
        "unexplained": None if result.unexplained is None else
        list(result.unexplained.variables),
        "fit_rms_m": {"nominal": result.fit.rms_nominal, "geometric": result.fit.rms_geometric,
                      "final": result.fit.rms_final},
        "held_out_rms_m": {"geometric": result.validation.rms_geometric,
                           "final": result.validation.rms_final},
        "held_out_final_over_floor": result.validation.rms_final / floor,
        "recommended": result.recommended,
        "seconds": time.perf_counter() - start,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=400, help="fit rows per scenario")
    parser.add_argument("--only", default=",".join(SCENARIOS), help="scenarios, comma-separated")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        out = [run(name, args.rows, Path(folder)) for name in args.only.split(",")]
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
