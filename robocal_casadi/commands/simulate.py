"""Write a synthetic dataset (robot, dataset file, table, truth) from a true model.

The true robot is the nominal one (--robot or --example) plus geometric errors
(--errors random, or --error by name); the instrument mounted on the flange gets its own
small error (--mounted-error); effects (--effect) act on the true robot; noise (--noise)
is added to what is measured. DIR receives robot.yaml (nominal), dataset.yaml, the
table (points.csv, touches.csv or scan.csv) and truth.yaml (everything that was true),
all at once: on any error nothing is written. Joint readings in the table are what the
controller reports; the measurements come from the true robot at the true joints.

Lengths and angles on the command line are in the robot file's units (the example
robots: industrial_6r, ur_type, prismatic_rrp in mm/deg, panda_7dof in m/rad).

--truth TRUTH.yaml (a truth.yaml that simulate wrote, with its robot.yaml beside it) keeps
that true robot: its parameters, effects and mounted instrument, the kind, the noise, the
units, the reference temperature and the payload's centre of mass; --seed then draws only
the new run (where the instrument or artifact stands, the configurations, the noise), so
the new folder is held-out data of the same robot. With the truth's own seed, --rows and
set-up options, the truth file is written again as it was.

--rows N counts readings (tracker, laser) or placements of the bar or artifact (the
cross bar: 4 touches each; an artifact plate: --sockets x --touches each).
--noise STD: tracker, per measured coordinate; touches, per coordinate of the probe's
seat in its socket; laser, of the laser distance.

--effect NAME[:SPEC], repeatable (values in SI, joints 1-based, several values
separated by '/', several joints by ','; without values the defaults shown are used):
{effects}

Example:
  robocal simulate --example industrial_6r --kind {tracker} --rows 500 \\
      --noise 0.01 --errors 0.5,0.05 --effect joint_compliance:2,3 --seed 1 --out sim
  robocal simulate --example industrial_6r --kind {tracker} --rows 400 \\
      --effect joint_coupling:5@6=2e-4/1e-4 --effect backlash:2=5e-4 --out sim2
  robocal simulate --truth sim/truth.yaml --rows 200 --seed 2 --out sim-validation
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from ..common.fields import check_magnitude
from ..common.units import Units, parse_units
from ..effects import EFFECTS
from ..errors import InputError
from ..instruments import kinds
from ..instruments.simulate import MAX_ROWS, READINGS, simulate, table_rows_of
from ..instruments.tracker import TrackerModel
from ..model.examples import ROBOTS
from ..model.robot import Robot, load_robot
from .arguments import add_force, output_folder, seed
from .console import summarise

# the example names its kind through the registry, the one place kind strings are spelled
__doc__ = (__doc__ or "").format(effects="\n".join(f"  {cls.simulation_syntax()}"
                                         for cls in EFFECTS.values()),
                                 tracker=TrackerModel.kind)
KIND_CHOICES = kinds()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--robot", metavar="ROBOT.yaml", help="nominal robot file")
    source.add_argument("--example", choices=sorted(ROBOTS), help="a built-in example robot")
    source.add_argument("--truth", metavar="TRUTH.yaml",
                        help="the true robot of an earlier simulation (its truth.yaml, with "
                        "robot.yaml beside it): new readings of that robot")
    parser.add_argument("--kind", choices=KIND_CHOICES,
                        help="dataset kind (required, unless --truth gives it)")
    parser.add_argument("--rows", "--count", dest="rows", type=int, default=100, metavar="N",
                        help="readings, or bar/artifact placements (default 100)")
    parser.add_argument("--noise", type=float, metavar="STD",
                        help="measurement noise std, robot length unit (default 0; with "
                        "--truth, the truth's)")
    errors = parser.add_mutually_exclusive_group()
    errors.add_argument("--errors", metavar="LENGTH,ANGLE",
                        help="random geometric errors: std of theta/d/a/alpha (and beta where "
                        "the file has one) of every joint, robot file units")
    errors.add_argument("--error", action="append", default=[], metavar="NAME=VALUE",
                        help="an explicit geometric error by parameter name (e.g. a2=0.3), "
                        "robot file units; repeatable")
    parser.add_argument("--mounted-error", type=float, metavar="STD",
                        help="std of the mounted instrument's offset from its nominal value "
                        "(default: the --errors length std)")
    parser.add_argument("--effect", action="append", default=[], metavar="NAME[:SPEC]",
                        help="an effect of the true robot (see above); repeatable")
    parser.add_argument("--payload", metavar="KG|LOW,HIGH",
                        help="write a payload column [kg]: a constant or uniform per row")
    parser.add_argument("--payload-com", metavar="X,Y,Z",
                        help="payload centre of mass in the flange frame (robot length unit)")
    parser.add_argument("--temperature", metavar="START,END",
                        help="write a temperature column drifting from START to END [C]")
    parser.add_argument("--reference-temperature", type=float, default=20.0, metavar="C",
                        help="T_ref of thermal drift [C] (default 20)")
    parser.add_argument("--readings", choices=READINGS, default="joints",
                        help="laser: joint readings or pendant poses (default joints)")
    parser.add_argument("--bar-length", type=float, metavar="L",
                        help="cross bar: arm length |AC| = |BD| (default 400 mm)")
    parser.add_argument("--socket-distance", type=float, metavar="D",
                        help="artifact plate: distance of neighbouring sockets (default 50 mm)")
    parser.add_argument("--sockets", type=int, default=2,
                        help="artifact plate: sockets on the plate (default 2)")
    parser.add_argument("--touches", type=int, default=5,
                        help="artifact plate: touches per socket and placement (default 5)")
    parser.add_argument("--sphere-radius", type=float, metavar="R",
                        help="laser: sphere radius (default 25 mm)")
    parser.add_argument("--units", metavar="LENGTH,ANGLE",
                        help="units of the dataset file and table, e.g. mm,deg (default: the "
                        "robot file's)")
    parser.add_argument("--seed", type=seed, default=0, help="random seed (default 0)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    add_force(parser)


def _floats(text: str, count: int | None, option: str) -> list[float]:
    """Comma-separated finite numbers (``count`` of them when given)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"expected comma-separated numbers, got {text!r}", where=option) from None
    if count is not None and len(values) != count:
        raise InputError(f"expected {count} numbers, got {text!r}", where=option)
    if not all(math.isfinite(v) for v in values):
        raise InputError(f"expected finite numbers, got {text!r}", where=option)
    return values


def _check_options(args: argparse.Namespace, robot: Robot) -> None:
    """Single-number options: finite, with the sign they need, of a plausible size."""
    L = robot.units.length_scale
    for option, value, rule in (("--noise", args.noise, ">=0"),
                                ("--mounted-error", args.mounted_error, ">=0"),
                                ("--bar-length", args.bar_length, ">0"),
                                ("--socket-distance", args.socket_distance, ">0"),
                                ("--sphere-radius", args.sphere_radius, ">0"),
                                ("--reference-temperature", args.reference_temperature, "")):
        if value is None:
            continue
        if not math.isfinite(value):
            raise InputError(f"expected a finite number, got {value}", where=option)
        if rule == ">=0" and value < 0:
            raise InputError(f"must not be negative, got {value:g}", where=option)
        if rule == ">0" and value <= 0:
            raise InputError(f"must be positive, got {value:g}", where=option)
        if rule:
            check_magnitude(value * L, "length", file=None, where=option, shown=value,
                            unit=robot.units.length)
    if args.sockets < 2:
        raise InputError(f"an artifact needs at least 2 sockets, got {args.sockets}",
                         where="--sockets")
    if args.touches < 1:
        raise InputError(f"expected at least 1 touch per socket, got {args.touches}",
                         where="--touches")
    if args.rows < 1:
        raise InputError(f"expected at least 1, got {args.rows}", where="--rows")
    for option, value in (("--sockets", args.sockets), ("--touches", args.touches)):
        if value > MAX_ROWS:
            raise InputError(f"at most {MAX_ROWS:,}, got {value:,}", where=option)
    table_rows = table_rows_of(args.kind, args.rows, args.sockets, args.touches)
    if table_rows > MAX_ROWS:
        raise InputError(f"{args.rows:,} would make a table of {table_rows:,} rows; at most "
                         f"{MAX_ROWS:,} rows are simulated", where="--rows")


def parse_effect_options(options: list[str], robot: Robot) -> dict:
    """``--effect`` strings as the ``effects`` mapping of ``simulate`` (SI)."""
    effects: dict = {}
    for option in options:
        name, _, spec = option.partition(":")
        name = name.strip()
        where = f"--effect {option}"
        if name not in EFFECTS:
            raise InputError(f"unknown effect {name!r}; expected one of {list(EFFECTS)}",
                             where=where)
        cls = EFFECTS[name]
        width = len(cls.simulation_default)
        if cls.per == "column":
            values = _floats(spec.replace("/", ","), width, where) if spec else \
                list(cls.simulation_default)
            effects[name] = values[0] if width == 1 else tuple(values)
            continue
        if not spec:
            key = "2@3" if cls.per == "pair" else "2,3"
            raise InputError(f"name the joints, e.g. {name}:{key}", where=where)
        entries = effects.setdefault(name, {})
        for item in spec.split(","):
            key_text, _, value_text = item.partition("=")
            key = cls.simulation_key(key_text, robot, where)
            values = _floats(value_text.replace("/", ","), None, where) if value_text else \
                list(cls.simulation_default)
            if not cls.accepts_simulation_values(len(values)):
                raise InputError(f"expected {width} numbers, got {value_text!r}", where=where)
            entries[key] = values[0] if width == 1 else tuple(values)
    return effects


HELD = ("--noise", "--errors", "--error", "--mounted-error", "--effect", "--payload-com",
        "--reference-temperature")  # what a held truth gives: refused beside --truth


def run(args: argparse.Namespace) -> int:
    output_folder(args.out, verb="simulate", force=args.force,
                  inputs=[args.robot, args.truth,
                          None if args.truth is None else Path(args.truth).parent / "robot.yaml"])
    if args.truth is not None:
        return _run_again(args)
    if args.kind is None:
        raise InputError("name the dataset kind (or give --truth)", where="--kind")
    if args.noise is None:
        args.noise = 0.0
    robot = load_robot(Path(args.robot)) if args.robot else ROBOTS[args.example]()
    _check_options(args, robot)
    L = robot.units.length_scale
    mounted_error = None if args.mounted_error is None else args.mounted_error * L
    geometric_errors = _geometric_errors(args, robot)
    payload = _payload(args)
    payload_com = None
    if args.payload_com:
        payload_com = [v * L for v in _floats(args.payload_com, 3, "--payload-com")]
    temperature = None
    if args.temperature:
        start, end = _floats(args.temperature, 2, "--temperature")
        temperature = (start, end)
    units = None
    if args.units:
        length, _, angle = args.units.partition(",")
        units = parse_units({"length": length.strip(), "angle": angle.strip()}, file=None,
                            key="--units")
    options: dict[str, float] = {}
    for key, default in (("bar_length", 0.4), ("socket_distance", 0.05),
                         ("sphere_radius", 0.025)):
        value = getattr(args, key)
        options[key] = default if value is None else value * L
    result = simulate(
        robot, args.kind, out_dir=Path(args.out), rows=args.rows, noise=args.noise * L,
        geometric_errors=geometric_errors, effects=parse_effect_options(args.effect, robot),
        seed=args.seed, units=units if isinstance(units, Units) else None,
        mounted_error=mounted_error, payload=payload, payload_com=payload_com,
        temperature=temperature, reference_temperature=args.reference_temperature,
        readings=args.readings, sockets=args.sockets, touches=args.touches, force=args.force,
        bar_length=options["bar_length"], socket_distance=options["socket_distance"],
        sphere_radius=options["sphere_radius"])
    return _written(args, result)


def _written(args: argparse.Namespace, result) -> int:
    kind = result.truth.kind
    print(f"wrote {result.rows} rows of {kind} to {Path(args.out)}/ "
          f"({result.table_path.name}, dataset.yaml, robot.yaml, truth.yaml)")
    summarise(args, kind=kind, rows=result.rows, out=str(args.out),
              dataset=str(result.dataset_path), table=str(result.table_path),
              truth=str(result.truth_path), held_truth=args.truth)
    return 0


def _run_again(args: argparse.Namespace) -> int:
    """``--truth``: new readings of a held truth (``simulate_again``)."""
    from ..instruments.held_truth import read_truth
    from ..instruments.simulate import simulate_again
    from .arguments import input_file

    given = {"--noise": args.noise is not None, "--errors": bool(args.errors),
             "--error": bool(args.error), "--mounted-error": args.mounted_error is not None,
             "--effect": bool(args.effect), "--payload-com": bool(args.payload_com),
             "--reference-temperature": args.reference_temperature != 20.0}
    clash = [option for option in HELD if given[option]]
    if clash:
        raise InputError(f"{', '.join(clash)} would change the true robot the truth file "
                         "holds; leave it out (or simulate a new robot without --truth)",
                         where="--truth")
    held = read_truth(input_file(args.truth, "truth file"))
    if args.kind is not None and args.kind != held.kind:
        raise InputError(f"the truth file is of kind {held.kind}, not {args.kind}",
                         where="--kind")
    args.kind = held.kind
    robot = held.nominal()
    args.noise = held.noise / robot.units.length_scale
    _check_options(args, robot)
    L = robot.units.length_scale
    units = None
    if args.units:
        length, _, angle = args.units.partition(",")
        units = parse_units({"length": length.strip(), "angle": angle.strip()}, file=None,
                            key="--units")
    result = simulate_again(
        args.truth, out_dir=Path(args.out), rows=args.rows, seed=args.seed,
        units=units if isinstance(units, Units) else None, payload=_payload(args),
        temperature=None if not args.temperature else tuple(
            _floats(args.temperature, 2, "--temperature")),
        readings=args.readings, sockets=args.sockets, touches=args.touches, force=args.force,
        bar_length=0.4 if args.bar_length is None else args.bar_length * L,
        socket_distance=0.05 if args.socket_distance is None else args.socket_distance * L,
        sphere_radius=0.025 if args.sphere_radius is None else args.sphere_radius * L)
    return _written(args, result)


def _payload(args: argparse.Namespace):
    """``--payload`` as a constant [kg], a ``(low, high)`` range or None."""
    if not args.payload:
        return None
    values = _floats(args.payload, None, "--payload")
    if len(values) not in (1, 2) or min(values) < 0:
        raise InputError(f"expected KG or LOW,HIGH (non-negative), got {args.payload!r}",
                         where="--payload")
    return values[0] if len(values) == 1 else (values[0], values[1])


def _geometric_errors(args: argparse.Namespace, robot: Robot
                      ) -> tuple[float, float] | dict[str, float] | None:
    """``--errors`` as ``(length std [m], angle std [rad])``, ``--error`` as errors by
    parameter name [SI], or None for neither."""
    L, A = robot.units.length_scale, robot.units.angle_scale
    if args.errors:
        length_std, angle_std = _floats(args.errors, 2, "--errors")
        if length_std < 0 or angle_std < 0:
            raise InputError(f"standard deviations must not be negative, got {args.errors!r}",
                             where="--errors")
        check_magnitude(length_std * L, "length", file=None, where="--errors",
                        shown=length_std, unit=robot.units.length)
        check_magnitude(angle_std * A, "angle", file=None, where="--errors",
                        shown=angle_std, unit=robot.units.angle)
        return (length_std * L, angle_std * A)
    if not args.error:
        return None
    registry = robot.parameters()
    per_parameter: dict[str, float] = {}
    for item in args.error:
        name, _, value = item.partition("=")
        name = name.strip()
        if name not in registry:
            raise InputError(f"unknown parameter {name!r}; valid names: "
                             f"{', '.join(registry.names)}", where=f"--error {item}")
        number = _floats(value, 1, f"--error {item}")[0]
        quantity_name = registry.quantity(name)
        if quantity_name in ("length", "angle"):
            check_magnitude(number * robot.units.scale(quantity_name), quantity_name,
                            file=None, where=f"--error {item}", shown=number,
                            unit=robot.units.unit_name(quantity_name))
        per_parameter[name] = number * robot.units.scale(registry.quantity(name))
    return per_parameter
