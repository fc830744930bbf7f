"""Calibrate a fleet of robots on a Dask cluster; write each robot's result and fleet.html/json.

FLEET.yaml lists the robots, each with a name, its datasets and optional held-out
datasets (the files `robocal calibrate` reads; paths relative to FLEET.yaml):

  robots:
    - name: cell3-r1
      datasets: [cell3/r1/tracker.yaml]
      validate: [cell3/r1/check.yaml]

Each robot is one task: it writes what `robocal calibrate` writes (result.json,
robot_calibrated.yaml, report.html) into DIR/<name>/. Without --scheduler a local
cluster of --workers processes (default: one per core) runs the tasks; with it, an
existing Dask cluster does (its workers must see the same paths). A rerun skips robots
whose input files (content) and settings are unchanged and whose result is complete.
A robot whose files are bad fails alone, with its one-line error in the summary.

DIR/fleet.json and DIR/fleet.html compare the robots: every robot's error before and
after, its effects, and the robots that stand out (an RMS error or a joint compliance
far above the fleet's, or, with --previous DIR, a joint offset that moved since that
run beyond its standard errors), with a plot per quantity across the robots.

With --learn-prior, every robot is first calibrated with the tolerance prior into
DIR/tolerance-prior/<name>/; the fleet's population prior is written to DIR/prior.yaml
and, per robot, the prior of the others (leave one out) to DIR/priors/<name>.yaml; every
robot is then calibrated with its own into DIR/<name>/, and fleet.html shows what the
prior changed (docs/methods.md#fleet-prior). --prior PRIOR.yaml instead uses one given
fleet prior for every robot.

Exit status: 0 when every robot was calibrated (or unchanged), 1 when any robot failed,
2 when FLEET.yaml or an option is bad (nothing is run).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..calibration import METHODS
from ..calibration.identification import CALIBRATION_LOSSES
from ..common.output import MARKER, Marker, atomic_file, read_marker, remove_stale_staging
from ..common.progress import Progress
from ..errors import InputError
from .arguments import add_allow_outside_data, positive_count
from .calibrate import REPORT_FIELDS, add_model_options, add_report_options, command_line_info
from .console import summarise

try:
    import fcntl
except ImportError:  # not POSIX: runs on one folder are not kept apart
    fcntl = None  # type: ignore[assignment]

LOCK = ".robocal-fleet.lock"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("fleet", type=Path, metavar="FLEET.yaml")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR",
                        help="output folder: DIR/<name>/ per robot, DIR/fleet.json, "
                        "DIR/fleet.html (kept between runs; unchanged robots are skipped)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="an existing Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: "
                        "a local cluster on this machine)")
    parser.add_argument("--workers", type=int, metavar="N",
                        help="worker processes of the local cluster (default: one per core)")
    parser.add_argument("--previous", type=Path, metavar="DIR",
                        help="an earlier fleet output folder: flag joint offsets that moved "
                        "since then beyond their standard errors")
    parser.add_argument("--recompute", action="store_true",
                        help="calibrate every robot again, even when unchanged")
    parser.add_argument("--no-diagnose", action="store_true",
                        help="stop after the geometric model")
    parser.add_argument("--method", choices=METHODS, default="lm",
                        help="the solver, as for calibrate (default lm)")
    parser.add_argument("--loss", choices=CALIBRATION_LOSSES, default="robust",
                        help="as for calibrate: robust (default) sets gross errors aside and "
                             "lists them; linear keeps every reading; huber down-weights")
    parser.add_argument("--max-iterations", type=int, default=200, metavar="N",
                        help="iterations allowed to each geometric fit (default 200)")
    parser.add_argument("--no-report", action="store_true",
                        help="skip each robot's report.html (fleet.html is always written)")
    parser.add_argument("--force", action="store_true",
                        help="write into an --out folder that robocal did not write")
    parser.add_argument("--learn-prior", action="store_true",
                        help="calibrate every robot again with the fleet prior learned from "
                             "the others; write DIR/prior.yaml from all of them")
    add_allow_outside_data(parser)
    add_model_options(parser)
    add_report_options(parser)


@contextlib.contextmanager
def _only_run(folder: Path) -> Iterator[None]:
    """Keep two fleet runs from writing into one folder at the same time."""
    if fcntl is None:
        yield
        return
    handle = os.open(folder / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(f"another fleet run is writing into {folder}; wait for it to end",
                             where="--out") from None
        except OSError:
            pass  # no locks on this file system
        yield
    finally:
        os.close(handle)


def _prepare_out(out: Path, force: bool) -> list[Path]:
    """The fleet folder is kept between runs (robots are replaced one by one), so it may
    be new, empty, or an earlier fleet run's; any other folder needs --force. Returns what
    it created (the folder, the marker) and the lock file to come, for ``_undo``."""
    if str(out).strip() == "":
        raise InputError("expected a folder name", where="--out")
    if out.exists() and not out.is_dir():
        raise InputError(f"{out} is a file; expected a folder", where="--out")
    marker = read_marker(out)
    if out.is_dir() and not force and any(out.iterdir()) and (marker is None
                                                              or marker.verb != "fleet"):
        by = "robocal did not write" if marker is None else \
            f"robocal {marker.verb or '(an earlier version)'} wrote"
        raise InputError(f"{out} is a folder {by} and it is not empty; name a new folder (or "
                         "give --force to write the fleet's results into it)", where="--out")
    created = [] if out.exists() else [out]
    out.mkdir(parents=True, exist_ok=True)
    if marker is None or marker.verb != "fleet":
        (out / MARKER).write_text(Marker("fleet").text())
        created.append(out / MARKER)
    if not (out / LOCK).exists():
        created.append(out / LOCK)
    return created


def _undo(out: Path, created: list[Path]) -> None:
    """Remove what ``_prepare_out`` and the lock added when the run wrote nothing else
    (a scheduler that cannot be reached, an interruption before the first robot)."""
    made = {p.name for p in created if p != out}
    if any(entry.name not in made for entry in out.iterdir()):
        return
    for path in created:
        if path != out:
            path.unlink(missing_ok=True)
    if out in created:
        with contextlib.suppress(OSError):
            out.rmdir()


def _apart(out: Path, previous: Path | None) -> None:
    """The earlier run compared with is read, never written: refuse an --out that is, holds
    or lies inside --previous."""
    if previous is None:
        return
    a, b = out.resolve(), previous.resolve()
    if a == b or a in b.parents or b in a.parents:
        raise InputError(f"{out} overlaps the earlier results --previous {previous}; this run "
                         "would replace what it compares with, so write it to another folder",
                         where="--out")


def _previous(folder: Path | None, fleet) -> dict | None:
    from ..fleet import previous_parameters

    if folder is None:
        return None
    if not folder.is_dir():
        raise InputError(f"{folder} is not a folder (expected an earlier fleet output)",
                         where="--previous")
    found = {}
    for robot in fleet.robots:
        parameters = previous_parameters(folder / robot.name)
        if parameters is not None:
            found[robot.name] = parameters
    return found


def _settings(args: argparse.Namespace):
    """The run's settings, the report's logo and templates checked first."""
    from ..fleet import Settings

    info = command_line_info(args)
    templates = args.report_templates
    return Settings(diagnose=not args.no_diagnose, method=args.method, loss=args.loss,
                    max_iterations=args.max_iterations, report=not args.no_report,
                    allow_outside_data=args.allow_outside_data, recompute=args.recompute,
                    rule=args.rule, profile=args.profile, pdf=args.pdf,
                    report_fields=tuple((n, getattr(info, n)) for n in REPORT_FIELDS
                                        if getattr(info, n)),
                    logo=None if info.logo is None else os.path.abspath(info.logo),
                    templates=None if templates is None else os.path.abspath(templates),
                    prior=None if args.prior is None else os.path.abspath(args.prior))


def run(args: argparse.Namespace) -> int:
    from ..fleet import load_fleet
    from ..fleet.engine import check_address, require_engine

    if args.scheduler is not None:
        check_address(args.scheduler)
    if args.workers is not None:
        positive_count(args.workers, "--workers")
        if args.scheduler is not None:
            raise InputError("--workers sizes the local cluster; an existing cluster "
                             "(--scheduler) has its own workers", where="--workers")
    positive_count(args.max_iterations, "--max-iterations")
    if args.learn_prior and args.prior is not None:
        raise InputError("--learn-prior learns the prior from this fleet; give it or --prior, "
                         "not both", where="--learn-prior")
    if (args.learn_prior or args.prior is not None) and args.rule != "prior":
        raise InputError("a fleet prior weighs the estimate: it needs --rule prior",
                         where="--learn-prior" if args.learn_prior else "--prior")
    if args.prior is not None:
        from ..calibration.population_prior import load_prior

        load_prior(args.prior)  # a bad file is refused before anything runs
    fleet = load_fleet(args.fleet)
    _apart(args.out, args.previous)
    previous = _previous(args.previous, fleet)  # read now: a robot may replace it below
    settings = _settings(args)
    require_engine()  # before the output folder is made
    created = _prepare_out(args.out, args.force)
    try:
        outcomes, summary = _run_locked(args, fleet, settings, previous)
    except BaseException:
        # The workers are gone with the cluster: a robot one of them was writing when the
        # run stopped (Ctrl-C) leaves no half-written staging behind.
        for folder in (args.out, *(args.out / robot.name for robot in fleet.robots)):
            remove_stale_staging(folder)
        _undo(args.out, created)
        raise
    print(f"{len(outcomes)} robots: {summary.count('calibrated')} calibrated, "
          f"{summary.count('unchanged')} unchanged (skipped), {summary.count('failed')} failed")
    for outcome in summary.failed:
        print(f"failed: {outcome.name}: {outcome.error}")
    if summary.note:
        print(f"not compared: {summary.note}")
    for reason in summary.reasons():
        print(f"stands out: {reason['robot']}: {reason['reason']}")
    print(f"wrote {args.out / 'fleet.json'}, {args.out / 'fleet.html'} and a folder per robot")
    summarise(args, robots=len(outcomes), calibrated=summary.count("calibrated"),
              unchanged=summary.count("unchanged"), failed=summary.count("failed"),
              failures={o.name: o.error for o in summary.failed},
              standing_out=[dict(r) for r in summary.reasons()], judged=summary.judged,
              note=summary.note, out=str(args.out))
    sys.stdout.flush()
    return 1 if summary.failed else 0


def _run_locked(args: argparse.Namespace, fleet, settings, previous) -> tuple[list, Any]:
    """Calibrate every robot into ``args.out`` under its lock; write the fleet's files."""
    from ..common.output import json_safe as _clean
    from ..fleet import summarise as compare
    from ..fleet.engine import run_fleet
    from ..fleet.page import render

    with _only_run(args.out):
        failed = 0
        with Progress("fleet", total=len(fleet.robots)) as bar:
            done = 0

            def show(outcome) -> None:
                nonlocal done, failed
                done += 1
                failed += not outcome.ok
                bar.update(done, f"robots ({failed} failed)" if failed else "robots")

            learned = ""
            if args.learn_prior:
                outcomes, learned = _learning(args, fleet, settings, show)
            else:
                outcomes = run_fleet(fleet, args.out, settings, scheduler=args.scheduler,
                                     workers=args.workers, on_done=show)
        summary = compare(fleet, outcomes, previous=previous,
                            previous_folder=None if args.previous is None else str(args.previous))
        content = summary.to_json()
        extra = ""
        if args.learn_prior:
            from ..fleet.learning import PRIOR_FILE, changes, table_html

            rows = changes(args.out, [robot.name for robot in fleet.robots])
            content["fleet_prior"] = {"prior": str(args.out / PRIOR_FILE), "robots": rows}
            extra = table_html(rows)
            print(learned)
        with atomic_file(args.out / "fleet.json") as staging:
            staging.write_text(json.dumps(_clean(content), indent=1) + "\n")
        with atomic_file(args.out / "fleet.html") as staging:
            staging.write_text(render(summary, extra))
    return outcomes, summary


def _learning(args: argparse.Namespace, fleet, settings, show) -> tuple[list, str]:
    """The two passes of --learn-prior (``fleet.learning``): the outcomes of the second
    and a line saying what was learned."""
    from dataclasses import replace

    from ..fleet.engine import run_fleet
    from ..fleet.learning import FIRST_PASS, PRIOR_FILE, PRIORS, learn_priors

    first = args.out / FIRST_PASS
    first.mkdir(exist_ok=True)
    run_fleet(fleet, first, settings, scheduler=args.scheduler, workers=args.workers)
    learned = learn_priors(args.out, [robot.name for robot in fleet.robots])
    outcomes = run_fleet(fleet, args.out, replace(settings, prior=os.path.abspath(
        args.out / PRIORS)), scheduler=args.scheduler, workers=args.workers, on_done=show)
    return outcomes, (f"fleet prior learned from {len(learned)} robots: "
                      f"{args.out / PRIOR_FILE}; each robot calibrated with the prior of the "
                      "others")
