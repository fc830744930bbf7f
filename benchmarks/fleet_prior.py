"""The fleet prior against the tolerance prior: simulated fleets and the real Pandas.

Simulated (``--part tracker`` and ``--part bar``): a fleet of one model (industrial_6r) whose
robots' geometric errors are a part the model shares (``SHARED`` of the tolerance, drawn
once per fleet) plus each robot's own (``OWN`` of the tolerance). ``--robots`` robots are
calibrated with all their data (30 tracker readings or 15 bar placements) under the
tolerance prior; their population prior is learned from them (``population_prior.learn``).
Then ``--next`` new robots of the model are measured with fewer and fewer poses and
calibrated three times on the same data, with the tolerance prior, with the fleet prior and
with the population itself (its true mean and spread: what the best learned prior could
know, so that what the learning loses and what no prior can give are told apart); each
calibration's TRUE work-cell RMS is the distance between the calibrated and the true
position of the instrument's point (tracker target, probe tip) over ``CELL_POSES`` random
configurations in the joint limits, after the best rigid motion (which registering the
robot to its cell fixes) is taken out. A robot off the model (own errors five times the
fleet's spread) is calibrated too, to see it refused and calibrated as before.

Real (``--part panda``): six Franka Pandas measured in sockets (panda-mukca and panda-fleet,
same robot file, same socket plate). Every robot is calibrated on all its placements under
the tolerance prior; then, for each robot with more than one placement, leave that robot
out: the prior from the others, the robot fitted on 16 touches of its first placement (the
first 8 touches in each socket), held-out RMS on its other placements, with the tolerance
prior and with the fleet prior.

``--own`` may list several sizes of each robot's own part (e.g. ``0.333,0.0333``): the
simulated parts run once for each, the first under ``tracker``/``bar``, the others under
``tracker own=<size>`` and ``bar own=<size>``.

Every fit runs without diagnosis and with the linear loss (the robust screening needs more
readings than the fewest counts here give); both priors see the same data.

    python benchmarks/fleet_prior.py [--part tracker,bar,panda] [--robots N] [--next M]
        [--shared DIR] [--out FILE]

``--shared DIR`` names the folder holding ``panda-mukca/`` and ``panda-fleet/`` (needed for
``--part panda``; default: the folder the environment variable ``ROBOCAL_PANDA_DATA``
names).

Prints and writes JSON.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from robocal_casadi.calibration.population_prior import (
    PopulationPrior,
    calibration_from,
    learn,
    posterior_content,
)
from robocal_casadi.calibration.prior import tolerance_of
from robocal_casadi.errors import RobocalError
from robocal_casadi.instruments.dataset import dataset_rows
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.job.run import JobOptions, calibrate_job
from robocal_casadi.model import examples
from robocal_casadi.model.kinematics import Kinematics
from robocal_casadi.model.parameters import perturbed_stems

SHARED = 2.0 / 3.0  # the model's shared errors, in tolerances (one standard deviation)
OWN = 1.0 / 3.0  # each robot's own errors, in tolerances
OFF = 5.0  # a robot off the model: own errors this many times the fleet's spread
NOISE = 0.02e-3  # [m] per coordinate
CELL_POSES = 400
KINDS = {"tracker": ("tracker_points", 30, (5, 10, 15, 20, 30)),
         # 5 readings, 5 placements: fewer residuals than unknowns, which only a fleet
         # prior calibrates (least squares alone cannot)
         "bar": ("cross_bar", 15, (5, 8, 10, 15))}
PANDA_TOUCHES = 8  # per socket of the first placement
PANDA_DATA = "ROBOCAL_PANDA_DATA"  # environment: the folder of the Pandas' data
NOT_HOLDING = "does not hold for this robot"  # calibrate's reason when it refuses


def options(prior=None) -> JobOptions:
    return JobOptions(diagnose=False, loss="linear", fleet_prior=prior)


def fleet_errors(robot, rng, shared, own_scale, off=False):
    """True errors by name [SI]: shared plus own (``off``: exactly ``own_scale``
    tolerances on every parameter, signs at random)."""
    names = [f"{s}{i}" for i, j in enumerate(robot.joints, 1) for s in perturbed_stems(robot, j)]
    registry = robot.parameters()
    tolerance = np.array([tolerance_of(n, registry.quantity(n), robot) for n in names])
    own = rng.choice([-1.0, 1.0], size=len(names)) if off else rng.normal(size=len(names))
    return {n: float(v) for n, v in zip(names, (shared + own_scale * own) * tolerance)}


def true_population(prior: PopulationPrior, robot, names, shared, own) -> PopulationPrior:
    """``prior`` with the population the fleet was drawn from in place of what was learned:
    mean ``shared`` tolerances and spread ``own`` tolerances on the perturbed ``names``, and
    on the rest (never off the drawing) a spread of a thousandth of the learned one."""
    registry = robot.parameters()
    mean = np.zeros(len(prior.names))
    variance = (1e-3 * prior.spread) ** 2
    for name, value in zip(names, shared):
        k = prior.names.index(name)
        tolerance = tolerance_of(name, registry.quantity(name), robot)
        mean[k], variance[k] = value * tolerance, (own * tolerance) ** 2
    return replace(prior, mean=mean, covariance=np.diag(variance))


def true_cell_rms(result, truth, kinematics: Kinematics, Q: np.ndarray) -> float:
    """RMS [m] over ``Q`` of calibrated minus true instrument point, rigid motion removed."""
    mounted = [v for v, _ in result.mounted.values()][:3]
    true_point = np.asarray(next(iter(truth.mounted.values())), float)
    calibrated = kinematics.points(Q, mounted, result.robot_calibrated.parameter_vector())
    true = kinematics.points(Q, true_point, truth.robot.parameter_vector())
    return rigid_rms(calibrated, true)


def rigid_rms(a: np.ndarray, b: np.ndarray) -> float:
    """RMS distance [m] of point sets ``a`` and ``b`` after the rigid motion best mapping
    ``a`` onto ``b`` (Kabsch)."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(u @ vt))
    rotation = (u @ np.diag([1.0, 1.0, d]) @ vt).T
    moved = (a - ca) @ rotation.T + cb
    return float(np.sqrt(np.mean(np.sum((moved - b) ** 2, axis=1))))


def cell_poses(robot, rng) -> np.ndarray:
    low = np.array([j.limits[0] for j in robot.joints])
    high = np.array([j.limits[1] for j in robot.joints])
    return rng.uniform(low, high, size=(CELL_POSES, robot.dof))


def subset(dataset, kind: str, count: int):
    """The first ``count`` readings or placements of ``dataset``."""
    if kind == "tracker_points":
        return dataset_rows(dataset, np.arange(dataset.rows) < count)
    poses = list(dict.fromkeys(np.asarray(dataset.pose).tolist()))[:count]
    return dataset_rows(dataset, np.isin(np.asarray(dataset.pose), poses))


def simulated(part: str, robots: int, next_robots: int, seed: int, folder: Path,
              noise: float = NOISE, own: float = OWN) -> dict:
    kind, full, counts = KINDS[part]
    robot = examples.industrial_6r()
    rng = np.random.default_rng(seed)
    names = [f"{s}{i}" for i, j in enumerate(robot.joints, 1) for s in perturbed_stems(robot, j)]
    shared = SHARED * rng.normal(size=len(names))
    kinematics = Kinematics(robot)
    Q = cell_poses(robot, np.random.default_rng(seed + 1))
    started = time.perf_counter()
    calibrations = []
    refused: list[str] = []
    for k in range(robots):
        data = simulate(robot, kind, out_dir=folder / f"{part}-fleet-{k}", rows=full,
                        noise=noise, geometric_errors=fleet_errors(robot, rng, shared, own),
                        seed=seed + 10 + k, progress=False)
        try:
            result = calibrate_job([data.load()], (), options())
        except RobocalError as error:  # a robot whose data refuse: it teaches nothing
            refused.append(f"robot-{k}: {error}")
            continue
        calibrations.append(calibration_from(posterior_content(result), Path(f"robot-{k}")))
    prior = learn(calibrations)
    population = true_population(prior, robot, names, shared, own)
    learned_s = time.perf_counter() - started
    rows = []
    for k in range(next_robots + 1):
        off = k == next_robots  # the last one is off the model
        data = simulate(robot, kind, out_dir=folder / f"{part}-next-{k}", rows=full,
                        noise=noise,
                        geometric_errors=fleet_errors(robot, rng, shared, OFF * own if off
                                                      else own, off=off),
                        seed=seed + 1000 + k, progress=False)
        dataset = data.load()
        for count in counts:
            part_data = subset(dataset, kind, count)
            entry = {"robot": k, "off_model": off, "count": count}
            for label, used in (("tolerance", None), ("fleet", prior),
                                ("population", population)):
                try:
                    result = calibrate_job([part_data], (), options(used))
                except RobocalError as error:
                    entry[label] = None
                    entry[f"{label}_refused"] = str(error)
                    continue
                use = result.prior.use
                entry[label] = true_cell_rms(result, data.truth, kinematics, Q) * 1e3
                if used is prior:
                    entry["belongs"] = use.belongs
                    entry["conflict"] = None if use.member is None else use.member.distance
                    entry["threshold"] = None if use.member is None else use.member.threshold
            rows.append(entry)
            print(json.dumps({part: entry}), flush=True)
    return {"kind": kind, "robot": robot.name, "fleet_robots": robots, "full": full,
            "counts": list(counts), "shared": SHARED, "own": own, "off": OFF,
            "noise_mm": noise * 1e3, "learn_s": learned_s, "rows": rows,
            "fleet_refused": refused,
            "summary": summarise(rows, counts, full)}


def summarise(rows: list[dict], counts, full: int) -> dict:
    """Per count, the median over the robots of the model of each prior's true RMS [mm],
    and the target: the fleet prior at a third of ``full`` against the tolerance at all."""
    members = [r for r in rows if not r["off_model"]]
    out = {}
    for count in counts:
        at = [r for r in members if r["count"] == count]
        tolerance = [r["tolerance"] for r in at if r["tolerance"] is not None]
        fleet = [r["fleet"] for r in at if r["fleet"] is not None]
        population = [r["population"] for r in at if r.get("population") is not None]
        out[str(count)] = {"tolerance_median_mm": _median(tolerance),
                           "fleet_median_mm": _median(fleet),
                           "population_median_mm": _median(population),
                           "tolerance_calibrated": len(tolerance),
                           "fleet_calibrated": len(fleet),
                           "belongs": sum(bool(r.get("belongs")) for r in at),
                           "robots": len(at)}
    third = min(counts, key=lambda c: abs(c - full / 3))
    fleet_third = {r["robot"]: r["fleet"] for r in members if r["count"] == third
                   and r["fleet"] is not None}
    tolerance_all = {r["robot"]: r["tolerance"] for r in members if r["count"] == full
                     and r["tolerance"] is not None}
    no_worse = [fleet_third[k] <= tolerance_all[k] for k in fleet_third if k in tolerance_all]
    population_third = {r["robot"]: r["population"] for r in members if r["count"] == third
                        and r.get("population") is not None}
    population_no_worse = [population_third[k] <= tolerance_all[k] for k in population_third
                           if k in tolerance_all]
    off = [r for r in rows if r["off_model"]]
    only_fleet = [r for r in members if r["tolerance"] is None and r["fleet"] is not None]
    return {"per_count": out, "third": third,
            "calibrated_only_with_the_fleet_prior": [{"robot": r["robot"], "count": r["count"],
                                                      "fleet": r["fleet"]}
                                                     for r in only_fleet],
            "fleet_at_third_no_worse_than_tolerance_at_all": f"{sum(no_worse)}/{len(no_worse)}",
            "fleet_third_median_mm": _median(list(fleet_third.values())),
            "population_at_third_no_worse_than_tolerance_at_all":
                f"{sum(population_no_worse)}/{len(population_no_worse)}",
            "population_third_median_mm": _median(list(population_third.values())),
            "tolerance_all_median_mm": _median(list(tolerance_all.values())),
            "off_model_refused": f"{sum(_told(r) for r in off)}/{len(off)}",
            "off_model_same_as_tolerance": all(
                (r["fleet"] is None and r["tolerance"] is None)
                or (r["fleet"] is not None and r["tolerance"] is not None
                    and math.isclose(r["fleet"], r["tolerance"], rel_tol=1e-6))
                for r in off if _told(r))}


def _told(row: dict) -> bool:
    """Whether the robot was told it does not belong: calibrated with the tolerances
    instead, or its data, too few for them, refused with that reason."""
    return row.get("belongs") is False or NOT_HOLDING in row.get("fleet_refused", "")


def _median(values: list[float]) -> float | None:
    return float(np.median(values)) if values else None


def panda_robots(shared: Path) -> dict[str, list[Path]]:
    """Each Panda's placement files (dataset files), first placement first."""
    out = {"panda-mukca": sorted((shared / "panda-mukca").glob("*.yaml"))}
    out["panda-mukca"] = [p for p in out["panda-mukca"] if p.name != "robot.yaml"]
    for folder in sorted((shared / "panda-fleet").iterdir()):
        if folder.is_dir():
            out[folder.name] = sorted(p for p in folder.glob("*.yaml") if p.name != "robot.yaml")
    return out


def first_touches(dataset):
    """The first ``PANDA_TOUCHES`` touches in each socket of the first placement."""
    pose = np.asarray(dataset.pose)
    first = pose == pose[0]
    keep = np.zeros(len(pose), dtype=bool)
    for socket in dict.fromkeys(dataset.point):
        rows = np.flatnonzero(first & (np.asarray(dataset.point) == socket))
        keep[rows[:PANDA_TOUCHES]] = True
    return dataset_rows(dataset, keep)


def pandas(shared: Path) -> dict:
    robots = panda_robots(shared)
    loaded = {name: [load_dataset(p) for p in files] for name, files in robots.items()}
    calibrations = {}
    for name, datasets in loaded.items():
        result = calibrate_job(datasets, (), options())
        calibrations[name] = calibration_from(posterior_content(result), Path(name))
    out = []
    for name, datasets in loaded.items():
        if len(datasets) < 2:
            continue
        prior = learn([c for other, c in calibrations.items() if other != name])
        fit = [first_touches(datasets[0])]
        entry: dict = {"robot": name, "fit_touches": len(fit[0].joints),
                       "held_out_placements": [p.stem for p in robots[name][1:]],
                       "prior_robots": len(prior.robots),
                       "odd_in_prior": [m.robot for m in prior.odd]}
        for label, used in (("tolerance", None), ("fleet", prior)):
            result = calibrate_job(fit, datasets[1:], options(used))
            entry[f"{label}_held_out_mm"] = result.validation.rms_geometric * 1e3
            if used is not None:
                use = result.prior.use
                entry["belongs"] = use.belongs
                entry["conflict"] = None if use.member is None else use.member.distance
                entry["threshold"] = None if use.member is None else use.member.threshold
        entry["ratio"] = entry["fleet_held_out_mm"] / entry["tolerance_held_out_mm"]
        all_fit = calibrate_job(datasets[:1], datasets[1:], options())
        entry["tolerance_full_placement_held_out_mm"] = all_fit.validation.rms_geometric * 1e3
        print(json.dumps({"panda": entry}), flush=True)
        out.append(entry)
    return {"robots": out, "at_most_0.85": sum(e["ratio"] <= 0.85 for e in out),
            "count": len(out)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", default="tracker,bar")
    parser.add_argument("--robots", type=int, default=12, help="fleet robots the prior learns from")
    parser.add_argument("--next", type=int, default=5, help="new robots of the model measured")
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--noise", type=float, default=NOISE * 1e3,
                        help="simulated noise per coordinate [mm] (default %(default)s)")
    parser.add_argument("--own", default=f"{OWN:.4g}",
                        help="each robot's own errors, in tolerances; a list runs each "
                        "(default %(default)s)")
    parser.add_argument("--shared", type=Path,
                        default=Path(os.environ[PANDA_DATA]) if os.environ.get(PANDA_DATA)
                        else None,
                        help="folder holding panda-mukca/ and panda-fleet/")
    parser.add_argument("--out", type=Path, default=None,
                        help="also write the JSON here (benchmarks/readme_measured.py --run "
                        "fleet_prior saves it with the facts of the run)")
    args = parser.parse_args()
    parts = args.part.split(",")
    if "panda" in parts and args.shared is None:
        parser.error(f"--part panda needs --shared DIR (or {PANDA_DATA} set)")
    report: dict = {}
    with tempfile.TemporaryDirectory() as folder:
        for part in parts:
            started = time.perf_counter()
            if part == "panda":
                report[part] = pandas(args.shared)
                report[part]["seconds"] = time.perf_counter() - started
                continue
            for k, own in enumerate(float(v) for v in args.own.split(",")):
                key = part if k == 0 else f"{part} own={own:g}"
                report[key] = simulated(part, args.robots, args.next, args.seed,
                                        Path(folder) / f"own{k}", args.noise * 1e-3, own)
                report[key]["seconds"] = time.perf_counter() - started
                started = time.perf_counter()
    text = json.dumps(report, indent=1)
    print(text)
    if args.out is None:
        return
    if args.out.exists():
        earlier = json.loads(args.out.read_text())
        earlier.update(report)
        text = json.dumps(earlier, indent=1)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
