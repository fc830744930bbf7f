"""Memory of reading a large data table: peak resident memory over the file's size.

Writes a tracker table (q1..q6, x, y, z, temperature; full-precision numbers, as
``robocal simulate`` writes them) of about ``--mib`` MiB, then reads it in a fresh
process with ``table.read_table`` and turns every column into floats (``Table.numbers``,
as ``load_dataset`` does). The child reports its peak resident set (``ru_maxrss``)
after reading and after importing alone; their difference is what the table cost.

Prints JSON: file size [MiB], rows, the peak increase [MiB], its ratio to the file
size, and the read time [s] (for information; no target is timed).

Run: ``python benchmarks/table_memory.py [--mib 250]`` (about 1 s per 4 MiB on one core).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

COLUMNS = [f"q{i}" for i in range(1, 7)] + ["x", "y", "z", "temperature"]
CHILD = """
import json, resource, sys, time
import numpy as np
from robocal_casadi.common.table import read_table
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
start = time.perf_counter()
table = read_table(sys.argv[1])
values = [table.numbers(c) for c in table.columns]
elapsed = time.perf_counter() - start
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"rows": len(table), "kib": after - before, "seconds": elapsed,
                  "sum": float(sum(np.sum(v) for v in values))}))
"""


def write_table(path: Path, mib: float, seed: int = 0) -> int:
    """A table of about ``mib`` MiB of random readings; returns its rows."""
    rng = np.random.default_rng(seed)
    block = 20_000
    rows = 0
    with path.open("w") as handle:
        handle.write(",".join(COLUMNS) + "\n")
        while handle.tell() < mib * 2**20:
            values = np.column_stack([rng.uniform(-3.1, 3.1, (block, 6)),
                                      rng.uniform(-2000.0, 2000.0, (block, 3)),
                                      rng.uniform(18.0, 26.0, (block, 1))])
            handle.write("\n".join(",".join(repr(float(v)) for v in row) for row in values))
            handle.write("\n")
            rows += block
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mib", type=float, default=64.0, help="table size [MiB]")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "points.csv"
        write_table(path, args.mib)
        size = path.stat().st_size / 2**20
        root = Path(__file__).resolve().parents[1]
        env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        child = subprocess.run([sys.executable, "-c", CHILD, str(path)], capture_output=True,
                               text=True, check=True, env=env, cwd=folder)
        measured = json.loads(child.stdout)
    peak = measured["kib"] / 1024.0
    print(json.dumps({"file_mib": round(size, 1), "rows": measured["rows"],
                      "peak_increase_mib": round(peak, 1),
                      "peak_over_file": round(peak / size, 2),
                      "read_seconds": round(measured["seconds"], 2)}, indent=1))


if __name__ == "__main__":
    main()
