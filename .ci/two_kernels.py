"""The same answer under a second BLAS kernel.

OpenBLAS picks its kernels by processor and ``OPENBLAS_CORETYPE`` forces one, so a second
kernel on this machine stands in for a user's other machine. Under the kernel this
environment runs and under a second one that this processor supports:

1. the README's worked example prints exactly the lines the README shows;
2. a seeded ``simulate`` of every kind (one with an effect) writes the same bytes;
3. one ``calibrate`` gives the same result.json numbers within 1e-6 relative (timings and
   iteration counts aside) and the same decisions.

A kernel the processor cannot run (illegal instruction) is skipped with a line saying so;
if no second kernel runs, the check says so and passes.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CANDIDATES = ("Haswell", "Sandybridge", "Nehalem", "Prescott", "Zen", "SkylakeX")


def _module(path: Path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _current_kernel() -> str:
    """The kernel this environment runs: OPENBLAS_CORETYPE, or what OpenBLAS chose."""
    if os.environ.get("OPENBLAS_CORETYPE"):
        return os.environ["OPENBLAS_CORETYPE"]
    from threadpoolctl import threadpool_info

    for pool in threadpool_info():
        if pool.get("internal_api") == "openblas":
            return str(pool.get("architecture"))
    return ""


def _environment(kernel: str) -> dict[str, str]:
    env = dict(os.environ)
    if kernel:
        env["OPENBLAS_CORETYPE"] = kernel
    return env


def _second_kernel(current: str) -> str | None:
    for kernel in CANDIDATES:
        if kernel.lower() == current.lower():
            continue
        probe = subprocess.run([sys.executable, "-c", "import numpy as n; a = n.ones((9, 9)); "
                                "print((a @ a).sum())"], env=_environment(kernel),
                               capture_output=True, text=True)
        if probe.returncode == 0:
            return kernel
        print(f"kernel {kernel}: this processor cannot run it (exit {probe.returncode}); "
              "skipped")
    return None


def _worked_example(kernel: str, folder: Path) -> list[str]:
    """Run the README's worked example in ``folder``; the last command's printed lines."""
    readme = _module(ROOT / "tests" / "test_readme_example.py")
    folder.mkdir(parents=True)
    output = ""
    for words in readme.worked_example_commands():
        done = subprocess.run([sys.executable, "-m", "robocal_casadi.cli", *words],
                              cwd=folder, env=_environment(kernel), capture_output=True,
                              text=True)
        if done.returncode != 0:
            sys.exit(f"worked example under {kernel}: robocal {' '.join(words)} exited "
                     f"{done.returncode}: {done.stderr.strip()[-400:]}")
        output = done.stdout
    return output.strip("\n").splitlines()


def main() -> int:
    current = _current_kernel()
    second = _second_kernel(current)
    if second is None:
        print(f"two-kernel check skipped: no kernel other than {current or 'the default'} "
              "runs on this processor")
        return 0
    kernels = (current, second)
    print(f"two-kernel check: {current or 'default'} and {second}")
    failures: list[str] = []
    readme = _module(ROOT / "tests" / "test_readme_example.py")
    expected = readme.printed_lines()
    same = _module(ROOT / "tests" / "test_same_everywhere.py")
    with tempfile.TemporaryDirectory() as scratch:
        root = Path(scratch)
        printed = {k: _worked_example(k, root / f"worked-{k or 'default'}") for k in kernels}
        for kernel, lines in printed.items():
            if lines != expected:
                diff = [f"  README: {a}\n  {kernel}: {b}"
                        for a, b in zip(expected, lines) if a != b]
                failures.append(f"worked example under {kernel} prints other lines than the "
                                "README:\n" + "\n".join(diff or [f"  {len(lines)} lines vs "
                                                                 f"{len(expected)}"]))
        cable_robot = root / "cable.yaml"  # the test's own cable arm, named in its arguments
        cable_robot.write_text(same.CABLE_ROBOT)
        for kernel in kernels:
            for name, args in same.SIMULATIONS.items():
                args = [a.replace("{cable_robot}", str(cable_robot)) for a in args]
                subprocess.run([sys.executable, "-m", "robocal_casadi.cli", "simulate", *args,
                                "--out", str(root / f"sim-{kernel}" / name), "--quiet"],
                               env=_environment(kernel), check=True)
        first, other = (root / f"sim-{k}" for k in kernels)
        for path in sorted(p for p in first.rglob("*") if p.is_file()):
            if path.read_bytes() != (other / path.relative_to(first)).read_bytes():
                failures.append(f"simulate: {path.relative_to(first)} differs between kernels")
        results = []
        for kernel in kernels:
            out = root / f"calibrated-{kernel}"
            subprocess.run([sys.executable, "-m", "robocal_casadi.cli", "calibrate",
                            str(first / "tracker" / "dataset.yaml"), "--out", str(out),
                            "--quiet"], env=_environment(kernel), check=True)
            results.append(json.loads((out / "result.json").read_text()))
        failures += [f"calibrate: {d}" for d in same._numbers_agree(*results)]
    for failure in failures:
        print(failure)
    print(f"two-kernel check: {'FAILED' if failures else 'the same'} "
          f"({len(failures)} difference(s))")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
