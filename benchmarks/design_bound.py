"""How much better than random plans any plan can be: the optimal approximate design.

For each set-up of ``benchmarks/planning.py`` (tracker points and cross bar, 6R and 7-DOF)
a pool of feasible candidates is drawn at two sizes, the tool-optimal approximate design
is found on it (``planning.approximate``), and its certified bound on the predicted tool
error of an N-pose plan is printed against the median of 40 random N-pose plans from the
same pool (``bound_over_random``; a plan beats random plans by 30% only where this is
below 0.7), with the asymptotic ratio of the optimal design to uniform weights (many
poses). A larger pool shows whether the pool limits the bound. Prints JSON.

    python benchmarks/design_bound.py [--quick]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# This folder holds a script named ``planning``: keep it off the import path so that
# ``import planning`` finds the package.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).parent.resolve()]

from planning.accuracy import tool_weights  # noqa: E402
from planning.approximate import design_value, optimal_approximate  # noqa: E402
from planning.candidates import generate  # noqa: E402
from planning.indices import index_value  # noqa: E402
from planning.information import Information  # noqa: E402
from planning.rows import RowModel  # noqa: E402
from planning.runnable import runnable_setup  # noqa: E402
from planning.selection import random_designs  # noqa: E402
from planning.setup import setup_from_dataset  # noqa: E402
from robocal_casadi.instruments.datasets import load_dataset  # noqa: E402

COUNTS = {"tracker_points": [12, 16, 24, 36], "cross_bar": [10, 14, 20, 28]}
POOLS = {"tracker_points": (360, 6000), "cross_bar": (120, 1200)}


def _setups(folder: Path) -> dict[str, Path]:
    """The set-up files of ``benchmarks/planning.py`` (loaded from that script)."""
    spec = importlib.util.spec_from_file_location("planning_benchmark",
                                                  Path(__file__).parent / "planning.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.setups(folder)


def case(path: Path, pools, seed: int = 0) -> dict:
    dataset = load_dataset(path, require_data=False)
    setup, kinematics, workspace = runnable_setup(setup_from_dataset(dataset))
    rng = np.random.default_rng(seed)
    rows = RowModel(setup, kinematics)
    weights = tool_weights(setup, workspace, rows.parameters, np.random.default_rng(seed))
    out = {"kind": dataset.kind, "robot": dataset.robot.name, "pools": []}
    for size in pools:
        started = time.perf_counter()
        candidates = generate(setup, workspace, size, rng)
        info = Information(rows.blocks(candidates), rows.parameters, rows.shared, weights)
        design = optimal_approximate(info, iterations=20000, settled=1.001)
        uniform = design_value(info, np.full(len(candidates), 1.0 / len(candidates)))
        ratios = {}
        for count in COUNTS[dataset.kind]:
            random = np.median([index_value("tool", info.spectrum(d, "tool"))
                                for d in random_designs(info, count, 40, rng)])
            ratios[count] = float(np.sqrt(max(design.lower, 0.0) / count) / random)
        out["pools"].append({"candidates": len(candidates), "bound_over_random": ratios,
                             "asymptotic_optimal_over_uniform": float(
                                 np.sqrt(design.value / uniform)),
                             "iterations": design.iterations,
                             "seconds": time.perf_counter() - started})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the smaller pools only")
    args = parser.parse_args()
    results = []
    with tempfile.TemporaryDirectory() as folder:
        for name, path in _setups(Path(folder)).items():
            kind = name.split("/")[1]
            pools = POOLS[kind][:1] if args.quick else POOLS[kind]
            results.append({"set_up": name, **case(path, pools)})
            print(json.dumps({name: [p["bound_over_random"] for p in results[-1]["pools"]]}),
                  file=sys.stderr, flush=True)
    print(json.dumps({"benchmark": "design_bound", "cases": results}, indent=2))


if __name__ == "__main__":
    main()
