"""The one registry of controller formats: what a calibration or a plan is written as.

A format is one file a controller, a driver or ROS reads. It comes in one of two shapes:

* ``ModelFormat``: the calibrated robot written for a controller (``robocal export``), from
  an ``ExportSource`` (the delivered geometry-only robot, the robot it started from, the
  user's URDF);
* ``ProgramFormat``: a plan written as a program the robot runs (``robocal plan``), from
  the planned joints in run order (and, for a scan, their instants).

Each says what it can express (``expresses``: geometry only, axis offsets only, joint
values, ...) and contributes one command-line flag with its help text; a format whose
controller takes only part of the geometry carries the ``Profile`` that
``calibrate --profile`` fits. Each built-in format is a small module of this package that
ends with ``register(...)``; a format written elsewhere does the same. The commands ask
``model_formats()``, ``program_formats()`` and ``profiles()``; none spells a format.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..model.robot import Robot


@dataclass(frozen=True)
class Profile:
    """The robot parameters a controller accepts, for ``calibrate --profile NAME``.

    ``parameters(robot)`` the names left free for a DH or modified-DH ``robot`` (the rest
    are held at nominal); ``urdf(robot)`` the same for a robot read from a URDF file, or
    None when the controller's set needs a DH file; ``phrase`` says the set in a few words
    for ``--profile``'s help, ``urdf_phrase`` what the URDF set is."""

    name: str
    phrase: str
    parameters: Callable[[Robot], tuple[str, ...]]
    urdf: Callable[[Robot], tuple[str, ...]] | None = None
    urdf_phrase: str = ""


@dataclass(frozen=True)
class ExportSource:
    """What ``robocal export`` writes from: ``calibrated`` (robot_calibrated.yaml, SI
    inside), ``nominal`` (the robot it started from, None for a URDF robot), ``like`` (the
    URDF given with ``--like``, or None), ``urdf`` (``like``, else the URDF the calibration
    read, else None) and the chain's ``base_link`` and ``tip_link`` in it."""

    calibrated: Robot
    nominal: Robot | None = None
    like: Path | None = None
    urdf: Path | None = None
    base_link: str | None = None
    tip_link: str | None = None


@dataclass(frozen=True)
class ModelFormat:
    """A calibrated robot as a controller reads it: ``write(source)`` the file's text;
    ``flag``, ``metavar`` and ``help`` its option of ``robocal export``; ``expresses`` what
    of the model it can hold; ``profile`` the parameter set to fit for it, if any."""

    name: str
    flag: str
    metavar: str
    help: str
    expresses: str
    write: Callable[[ExportSource], str]
    profile: Profile | None = None


@dataclass(frozen=True)
class ProgramFormat:
    """A plan as a robot program: ``write(robot, joints, times)`` the program's text for
    ``joints`` (N x dof, [rad] or [m], run order) and, for a scan, ``times`` (N,) [s] (None
    for poses with a pause each); ``flag``, ``metavar`` and ``help`` its option of
    ``robocal plan``; ``expresses`` what the program holds; ``profile`` the parameter set
    its controller accepts, if any."""

    name: str
    flag: str
    metavar: str
    help: str
    expresses: str
    write: Callable[[Robot, np.ndarray, np.ndarray | None], str]
    profile: Profile | None = None


Format = ModelFormat | ProgramFormat
FORMATS: dict[str, Format] = {}


def register(fmt: Format) -> Format:
    """Add ``fmt`` after the formats registered before it; its flag and profile then appear
    on the command line. A name, flag or profile name already taken is refused."""
    taken = [f for f in FORMATS.values() if f.name == fmt.name or f.flag == fmt.flag
             or (fmt.profile is not None and f.profile is not None
                 and f.profile.name == fmt.profile.name)]
    if taken:
        raise ValueError(f"format {fmt.name!r} ({fmt.flag}) clashes with {taken[0].name!r}, "
                         "registered already")
    FORMATS[fmt.name] = fmt
    return fmt


def model_formats() -> tuple[ModelFormat, ...]:
    """The formats ``robocal export`` writes, in registration order."""
    return tuple(f for f in FORMATS.values() if isinstance(f, ModelFormat))


def program_formats() -> tuple[ProgramFormat, ...]:
    """The programs ``robocal plan`` writes, in registration order."""
    return tuple(f for f in FORMATS.values() if isinstance(f, ProgramFormat))


def profiles() -> tuple[Profile, ...]:
    """The controller parameter sets ``calibrate --profile`` offers, in registration order."""
    return tuple(f.profile for f in FORMATS.values() if f.profile is not None)


def option_name(fmt: Format) -> str:
    """The ``argparse`` destination of ``fmt``'s flag (``--ur-calibration`` ->
    ``ur_calibration``)."""
    return fmt.flag.lstrip("-").replace("-", "_")


def profile_parameters(name: str, robot: Robot) -> tuple[str, ...]:
    """The robot parameter names profile ``name`` leaves free for ``robot``; an unknown
    name, or a URDF robot under a profile that needs a DH file, is an ``InputError``."""
    found = {p.name: p for p in profiles()}
    if name not in found:
        raise InputError(f"unknown profile {name!r}; expected one of {list(found)}",
                         where="--profile")
    profile = found[name]
    if robot.convention != "urdf":
        return profile.parameters(robot)
    if profile.urdf is None:
        usable = "; ".join(f"--profile {p.name} ({p.urdf_phrase})" for p in found.values()
                           if p.urdf is not None)
        raise InputError(f"profile {name} needs a DH or modified-DH robot file; a URDF "
                         f"robot's controller-ready set is {usable}", where="--profile")
    return profile.urdf(robot)
