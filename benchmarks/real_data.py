"""Calibration on real data: the package's copies, or the full public data sets.

Each set is calibrated on part of its data and validated on the rest:

* UR10 laser tracker, series A and series D (each on its own: different mountings),
  three quarters of the poses fit, every fourth pose held out;
* Franka Panda in plate sockets: seven placements fit, two whole placements held out,
  for several choices of the held-out pair.

Prints JSON: RMS [mm] nominal / geometric / final on fit and held-out data, the effects
diagnosis added, identifiable parameter count, condition number and time.

    python benchmarks/real_data.py [--shared DIR] [--quick]

Without ``--shared`` the data come from ``robocal_casadi/data``: UR10 series D as shipped
(already split, every fourth pose held out) and the Panda placements; series A is not
shipped. ``--shared DIR`` names a folder holding ``ur10-ipa/series_D.yaml``,
``ur10-ipa/series_A.yaml`` and ``panda-mukca/`` converted from the public data sets
(see ``robocal_casadi/data/README.md``), and runs both series.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from robocal_casadi.calibration import calibrate
from robocal_casadi.instruments.datasets import load_dataset

PANDA = ("back_left", "back_right", "front_center", "front_left", "front_right", "high",
         "mid-high", "mid_left", "mid_right")


def split_every_fourth(dataset):
    """(fit, held out): rows 4, 8, 12, ... held out (1-based), the rest fit."""
    rows = np.arange(dataset.rows)
    held = rows % 4 == 3

    def take(mask):
        extras = {k: v[mask] for k, v in dataset.extras.items()}
        return replace(dataset, joints=dataset.joints[mask], measured=dataset.measured[mask],
                       extras=extras, path=dataset.path.with_name(
                           dataset.path.stem + ("_validation" if mask is held else "_fit") +
                           dataset.path.suffix))

    return take(~held), take(held)


def summary(result, seconds: float) -> dict:
    mm = 1e3
    out = {
        "identifiable": len(result.identifiability.identifiable),
        "condition_number": result.condition_number,
        "fit_mm": {k: v * mm for k, v in vars(result.fit).items()},
        "effects": [{"name": e.name, "joints": list(e.joints), "summary": e.summary}
                    for e in result.effects],
        "seconds": seconds,
    }
    if result.validation is not None:
        out["validation_mm"] = {k: v * mm for k, v in vars(result.validation).items()}
    return out


def run_tracker(path: Path, diagnose: bool) -> dict:
    if path.is_file():
        fit, held = split_every_fourth(load_dataset(path))
    else:  # the package's copy of the series, already split the same way
        fit = load_dataset(path.with_name(path.stem + "_fit.yaml"))
        held = load_dataset(path.with_name(path.stem + "_validation.yaml"))
    start = time.perf_counter()
    result = calibrate([fit], [held], diagnose=diagnose)
    return {"set": path.stem, "rows_fit": fit.rows, "rows_validation": held.rows,
            **summary(result, time.perf_counter() - start)}


def run_panda(folder: Path, held_out: tuple[str, str], diagnose: bool) -> dict:
    fit = [load_dataset(folder / f"{n}.yaml") for n in PANDA if n not in held_out]
    validation = [load_dataset(folder / f"{n}.yaml") for n in held_out]
    start = time.perf_counter()
    result = calibrate(fit, validation, diagnose=diagnose)
    spread = _socket_spread(result)
    return {"set": "panda", "held_out": list(held_out),
            **summary(result, time.perf_counter() - start),
            "validation_touch_spread_mm": spread}


def _socket_spread(result) -> dict:
    """RMS distance of held-out touches from their socket [mm], nominal and final."""
    out = {}
    for stage in ("nominal", "final"):
        values = [getattr(r, f"errors_{stage}")[r.rows >= 0] for r in result.validation_residuals]
        flat = np.concatenate(values)
        out[stage] = float(np.sqrt(np.mean(flat**2)) * 1e3)
    out["reduction"] = 1 - out["final"] / out["nominal"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--shared", type=Path, default=None, metavar="DIR",
                        help="folder of the full data sets (default: the package's copies)")
    parser.add_argument("--quick", action="store_true", help="series D and one Panda split only")
    parser.add_argument("--no-diagnose", action="store_true")
    args = parser.parse_args()
    diagnose = not args.no_diagnose
    results = []
    if args.shared is None:
        from robocal_casadi.commands.demo import data_folder

        args.shared = data_folder()
    shipped = not (args.shared / "ur10-ipa" / "series_A.yaml").is_file()
    series = ("series_D",) if args.quick or shipped else ("series_D", "series_A")
    for name in series:
        results.append(run_tracker(args.shared / "ur10-ipa" / f"{name}.yaml", diagnose))
        print(json.dumps(results[-1]), flush=True)
    splits = [("mid-high", "mid_right")] if args.quick else \
        [("mid-high", "mid_right"), ("back_left", "front_right"), ("high", "front_center")]
    for pair in splits:
        results.append(run_panda(args.shared / "panda-mukca", pair, diagnose))
        print(json.dumps(results[-1]), flush=True)
    print(json.dumps({"benchmark": "real_data", "results": results}, indent=2))


if __name__ == "__main__":
    main()
