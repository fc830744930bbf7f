"""Learn a fleet prior of one robot model from calibration result folders.

Each RESULT_DIR is a folder `robocal calibrate` (or `robocal fleet`) wrote for one robot;
all must come from the same nominal robot file (same model name, convention and nominal
values), else the first folder that differs is named and nothing is written. The robots'
geometric estimates and their estimation covariances (geometry_posterior.json) give the
model's population: the mean deviation of every parameter from the drawing and their
covariance, each robot's own estimation uncertainty taken out of the spread and each
parameter weighed by how well each robot's data saw it (an empirical-Bayes random-effects
model, fitted by EM; docs/methods.md#fleet-prior). With few robots the covariance is
shrunk toward the tolerances; a robot off the model is named and down-weighted.

PRIOR.yaml then goes to `robocal calibrate ... --prior PRIOR.yaml`.

Example:
  robocal prior cell1/robot-a cell1/robot-b cell2/robot-c --out panda.prior.yaml
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from ..calibration.population import PSEUDO_ROBOTS
from ..calibration.population_prior import (
    PopulationPrior,
    learn,
    read_calibration,
    save_prior,
)
from ..errors import InputError
from .console import summarise


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("results", nargs="+", type=Path, metavar="RESULT_DIR",
                        help="calibration result folders of robots of one model")
    parser.add_argument("--out", type=Path, required=True, metavar="PRIOR.yaml",
                        help="the fleet prior file to write")
    parser.add_argument("--pseudo-robots", type=float, default=PSEUDO_ROBOTS, metavar="N",
                        help="how many robots the tolerance prior counts as when the "
                             f"covariance is shrunk toward it (default {PSEUDO_ROBOTS:g})")


def summary(prior: PopulationPrior) -> str:
    """A few lines for the terminal: the robots, what they saw, the odd ones."""
    seen = sum(1 for k in prior.seen_by if k > 0)
    lines = [f"fleet prior of {prior.model!r} from {len(prior.robots)} robots: "
             f"{len(prior.names)} parameters, {seen} seen by at least one robot"]
    units = prior.units
    order = np.argsort(-np.abs(prior.mean) / np.maximum(prior.spread, 1e-300))
    shown = [int(k) for k in order[:5] if prior.seen_by[int(k)] > 0]
    if shown:
        lines.append("largest shared deviations (mean +- spread): " + ", ".join(
            f"{prior.names[k]} {prior.mean[k] / units.scale(prior.quantities[k]):+.3g} +- "
            f"{prior.spread[k] / units.scale(prior.quantities[k]):.3g} "
            f"{units.unit_name(prior.quantities[k])}" for k in shown))
    for member in prior.odd:
        lines.append(f"ODD ROBOT {member.robot}: off the others beyond its noise "
                     f"(statistic {member.distance:.3g} over {member.seen} directions, limit "
                     f"{member.threshold:.3g}); down-weighted to {member.weight:.2g}")
    if not prior.odd:
        lines.append("every robot belongs to the population")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    if not (math.isfinite(args.pseudo_robots) and args.pseudo_robots > 0):
        raise InputError(f"expected a positive number, got {args.pseudo_robots}",
                         where="--pseudo-robots")
    if args.out.suffix.lower() not in (".yaml", ".yml"):
        raise InputError("expected a .yaml file name", where="--out")
    seen: dict[Path, Path] = {}
    for folder in args.results:
        key = folder.resolve()
        if key in seen:
            raise InputError(f"given twice ({seen[key]} and {folder}); each robot counts once",
                             file=folder)
        seen[key] = folder
    calibrations = [read_calibration(folder) for folder in args.results]
    prior = learn(calibrations, pseudo_robots=args.pseudo_robots)
    save_prior(prior, args.out)
    print(summary(prior))
    print(f"wrote {args.out}")
    summarise(args, model=prior.model, robots=list(prior.robots), count=len(prior.robots),
              odd=[m.robot for m in prior.odd], out=str(args.out))
    return 0
