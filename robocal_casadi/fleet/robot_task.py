"""One robot of a fleet, calibrated as one task on a worker.

``calibrate_robot`` reads the robot's datasets, hashes every input file's content with
the calibration settings, and either finds the robot's folder ``DIR/<name>/`` already
complete for exactly these inputs (status ``unchanged``: nothing is computed) or runs
the same calibration as ``robocal calibrate`` and writes the same files there with the
same writer. Last it writes ``fleet_robot.json`` beside them: the input hash, the files
written and the few numbers the fleet summary compares, in SI. That record is the mark
of a complete result: a run killed before it is written is computed again next time.

Whatever goes wrong with one robot (a bad file, a solver that does not converge, a
folder that cannot be written) ends that task with a one-line error in its outcome; the
task itself never raises, so other robots are not affected.
"""

from __future__ import annotations

import hashlib
import json
import os
import resource
import sys
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..common.output import atomic_file, not_replacing_inputs, replace_refusal, written_by_robocal
from ..effects import EFFECTS
from ..errors import InputError, RobocalError
from .spec import FleetRobot

if TYPE_CHECKING:
    from ..calibration.identification import CalibrationLoss
    from ..calibration.solver import Method

RECORD = "fleet_robot.json"
RECORD_VERSION = 2  # 2: results carry what is delivered and the predicted accuracy


@dataclass(frozen=True)
class Settings:
    """Calibration settings shared by every robot of a run (those of ``robocal
    calibrate``), and whether to recompute robots whose result is complete."""

    diagnose: bool = True
    method: Method = "lm"
    loss: CalibrationLoss = "robust"
    max_iterations: int = 200
    report: bool = True
    allow_outside_data: bool = False
    recompute: bool = False
    rule: str = "prior"
    profile: str | None = None
    pdf: bool = False
    report_fields: tuple[tuple[str, str], ...] = ()  # (ReportInfo field, text) given for all
    logo: str | None = None  # path of the reports' logo
    templates: str | None = None  # folder of report templates
    # a fleet prior for every robot: a file, or a folder holding ``<robot name>.yaml``
    prior: str | None = None

    def hashed(self) -> dict:
        """The settings a result depends on (not ``recompute``)."""
        values = asdict(self)
        values.pop("recompute")
        return values

    def read_files(self) -> list[tuple[str, Path]]:
        """(role, path) of the files the settings name for reading: the logo and every
        file of the templates folder."""
        files = [] if self.logo is None else [("logo", Path(self.logo))]
        if self.templates is not None:
            files += [("templates", p) for p in sorted(Path(self.templates).iterdir())
                      if p.is_file()]
        return files

    def prior_of(self, name: str) -> Path | None:
        """The fleet prior file robot ``name`` is calibrated with (None: the tolerances)."""
        if self.prior is None:
            return None
        path = Path(self.prior)
        return path / f"{name}.yaml" if path.is_dir() else path

    def report_info(self, datasets):
        """The report's fields: the datasets' ``report:`` blocks, then the run's own."""
        from ..report.info import ReportInfo, info_from_dataset_file

        info = ReportInfo()
        for dataset in datasets:
            info = info.merged(info_from_dataset_file(dataset.path))
        given = ReportInfo(**dict(self.report_fields),
                           logo=None if self.logo is None else Path(self.logo))
        return info.merged(given)


@dataclass(frozen=True)
class RobotOutcome:
    """What became of one robot.

    ``status`` is ``calibrated``, ``unchanged`` (complete for the same inputs, skipped)
    or ``failed`` (``error`` the one-line reason). ``summary`` (SI, see
    ``robot_summary``) is None for a failed robot. ``seconds`` and ``cpu_seconds`` [s]
    are the task's wall and processor time; ``worker`` names the process that ran it;
    ``memory`` and ``peak_memory`` [bytes] are that process's resident size after the
    task and the most it has held so far; ``finished`` when the task ended.
    """

    name: str
    status: str
    error: str | None = None
    summary: dict | None = None
    input_hash: str | None = None
    warnings: tuple[str, ...] = ()
    seconds: float = 0.0
    cpu_seconds: float = 0.0
    worker: str = ""
    memory: int = 0
    peak_memory: int = 0
    finished: float = 0.0  # [s] since the epoch

    @property
    def ok(self) -> bool:
        return self.status != "failed"


@dataclass
class _Clock:
    wall: float = field(default_factory=time.perf_counter)
    cpu: float = field(default_factory=time.process_time)


def one_line(error: BaseException) -> str:
    """The one line a person reads for ``error``: as the command line prints it."""
    if isinstance(error, RobocalError):
        text = str(error)
    elif isinstance(error, OSError):
        where = f"{error.filename}: " if error.filename else ""
        text = where + (error.strerror or str(error))
    else:
        text = f"unexpected {type(error).__name__}: {error}"
    return " ".join(text.split())


def input_files(datasets, validation) -> list[tuple[str, Path]]:
    """(role, path) of every file the calibration reads: each dataset file, its table
    and its robot file, fitted ones first."""
    files = []
    for role, group in (("fit", datasets), ("validate", validation)):
        for dataset in group:
            for path in (dataset.path, dataset.data_path, dataset.robot_path):
                if path is not None:
                    files.append((role, Path(path)))
    return files


def input_hash(files: list[tuple[str, Path]], settings: Settings) -> str:
    """SHA-256 over the settings and, in order, each input file's role, name and bytes."""
    from .. import __version__

    digest = hashlib.sha256()
    digest.update(json.dumps({"robocal": __version__, "settings": settings.hashed()},
                             sort_keys=True).encode())
    for role, path in files:
        data = path.read_bytes()
        digest.update(f"\0{role}\0{path.name}\0{len(data)}\0".encode())
        digest.update(data)
    return digest.hexdigest()


def complete_record(folder: Path, digest: str) -> dict | None:
    """The record of ``folder`` when it is complete for inputs hashing to ``digest``:
    written by robocal, the record readable and matching, every file it lists present."""
    if not written_by_robocal(folder):
        return None
    try:
        record = json.loads((folder / RECORD).read_text())
    except (OSError, ValueError):
        return None
    if (not isinstance(record, dict) or record.get("version") != RECORD_VERSION
            or record.get("input_hash") != digest or not isinstance(record.get("summary"), dict)
            or not isinstance(record.get("files"), list)):
        return None
    if not all(isinstance(name, str) and (folder / name).is_file() for name in record["files"]):
        return None
    return record


def rms_standard_error(errors: np.ndarray) -> float | None:
    """[m] The standard error of the RMS of ``errors`` [m] that the scatter of the errors
    themselves implies: the mean square's standard error ``sd(e^2) / sqrt(n)``, carried to
    the RMS by its derivative ``1 / (2 RMS)``. What the noise of one robot's fit leaves
    uncertain in its RMS (None for fewer than two errors or a zero RMS)."""
    errors = np.asarray(errors, dtype=float)
    errors = errors[np.isfinite(errors)]
    squares = errors ** 2
    if len(squares) < 2 or not squares.mean() > 0:
        return None
    return float(np.std(squares, ddof=1) / np.sqrt(len(squares))
                 / (2.0 * np.sqrt(squares.mean())))


def _rms_noise(residuals) -> dict | None:
    """Per stage (``rms_nominal``, ...), the standard error [m] of the RMS of ``residuals``'
    errors pooled (``rms_standard_error``); None without residuals."""
    if not residuals:
        return None
    return {f"rms_{stage}": rms_standard_error(np.concatenate(
        [getattr(r, f"errors_{stage}") for r in residuals]))
        for stage in ("nominal", "geometric", "final")}


def robot_summary(result) -> dict:
    """The numbers the fleet compares, SI: RMS errors [m] before and after (fit and
    validation) with their standard errors (``fit_std``, ``validation_std``, from the
    scatter of each robot's own errors: ``rms_standard_error``), the effects added
    (parameters and standard errors in their unit), the gravity compliance per joint
    [rad/Nm] and each joint's offset (``theta_i`` [rad] of a revolute joint, ``d_i`` [m]
    of a prismatic one) with its standard error."""
    def rms(summary):
        if summary is None:
            return None
        return {"rms_nominal": summary.rms_nominal, "rms_geometric": summary.rms_geometric,
                "rms_final": summary.rms_final}

    effects = []
    compliance = {}
    for effect in result.effects:
        # a learned map's gain has no standard error (None)
        std = {k: None if v is None else float(v) for k, v in (effect.std or {}).items()}
        effects.append({"name": effect.name, "joints": list(effect.joints), "unit": effect.unit,
                        "parameters": {k: float(v) for k, v in effect.parameters.items()},
                        "std": std})
        cls = EFFECTS.get(effect.name)
        keys = {j: cls.compliance_parameter(j) for j in effect.joints} if cls else {}
        for joint, key in keys.items():
            if key is not None and key in effect.parameters:
                compliance[str(joint)] = {"value": float(effect.parameters[key]),
                                          "std": std.get(key)}
    estimates = {p.name: p for p in result.parameters}
    offsets = {}
    for index, joint in enumerate(result.robot_nominal.joints, start=1):
        name = f"theta{index}" if joint.revolute else f"d{index}"
        estimate = estimates.get(name)
        if estimate is None:
            continue
        offsets[str(index)] = {"name": name, "quantity": estimate.quantity,
                               "estimate": float(estimate.estimate),
                               "std": None if estimate.std is None else float(estimate.std),
                               "identifiable": bool(estimate.identifiable)}
    aside = sum(len(e.lines) for e in result.rejected if e.role == "fit")
    kept = sum(len(r.joints) if r.joints is not None else len(r.errors_final)
               for r in result.residuals)
    rejected = {"units": sum(e.role == "fit" for e in result.rejected), "readings": aside,
                "of": kept + aside, "share": aside / max(kept + aside, 1)}
    return {"units": result.units.as_dict(), "fit": rms(result.fit), "rejected": rejected,
            "validation": rms(result.validation), "fit_std": _rms_noise(result.residuals),
            "validation_std": _rms_noise(result.validation_residuals), "effects": effects,
            "compliance": compliance, "joint_offsets": offsets,
            "recommended": result.recommended,
            "delivered_model": None if result.delivered is None else result.delivered.model,
            "predicted_accuracy": None if result.predicted_accuracy is None else {
                "rms": result.predicted_accuracy.rms, "p95": result.predicted_accuracy.p95,
                "max": result.predicted_accuracy.max,
                "rms_band": None if result.predicted_accuracy.band is None else list(
                    result.predicted_accuracy.band)},
            "condition_number": float(result.condition_number)}


def _memory() -> tuple[int, int]:
    """This process's resident size now and at most so far [bytes]."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    peak *= 1 if sys.platform == "darwin" else 1024  # Linux reports kilobytes
    try:
        import psutil

        now = psutil.Process().memory_info().rss
    except ImportError:
        now = peak
    return now, peak


def _finish(clock: _Clock, name: str, status: str, caught: list, **fields) -> RobotOutcome:
    now, peak = _memory()
    messages = tuple(dict.fromkeys(" ".join(str(w.message).split()) for w in caught))
    return RobotOutcome(name=name, status=status, warnings=messages,
                        seconds=time.perf_counter() - clock.wall,
                        cpu_seconds=time.process_time() - clock.cpu,
                        worker=f"{os.uname().nodename}:{os.getpid()}", memory=now,
                        peak_memory=peak, finished=time.time(), **fields)


def calibrate_robot(robot: FleetRobot, out: str | Path, settings: Settings) -> RobotOutcome:
    """Calibrate ``robot`` into ``out/<name>/`` unless complete for the same inputs; never
    raises (see the module docstring)."""
    from ..instruments.datasets import load_dataset

    clock = _Clock()
    folder = Path(out) / robot.name
    digest = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            outside = settings.allow_outside_data
            datasets = [load_dataset(p, allow_outside_data=outside) for p in robot.datasets]
            validation = [load_dataset(p, allow_outside_data=outside) for p in robot.validate]
            files = input_files(datasets, validation) + settings.read_files()
            prior = settings.prior_of(robot.name)
            if prior is not None:
                files.append(("prior", prior))
            digest = input_hash(files, settings)
            record = None if settings.recompute else complete_record(folder, digest)
            if record is not None:
                return _finish(clock, robot.name, "unchanged", caught,
                               summary=record["summary"], input_hash=digest)
            summary = _calibrate(robot, folder, settings, datasets, validation, files, digest)
            return _finish(clock, robot.name, "calibrated", caught, summary=summary,
                           input_hash=digest)
        except Exception as error:  # noqa: BLE001 - one robot's failure is its own
            return _finish(clock, robot.name, "failed", caught, error=one_line(error),
                           input_hash=digest)


def _prior(settings: Settings, name: str):
    """The fleet prior robot ``name`` is calibrated with, loaded (None: the tolerances)."""
    from ..calibration.population_prior import load_prior

    path = settings.prior_of(name)
    return None if path is None else load_prior(path)


def _calibrate(robot: FleetRobot, folder: Path, settings: Settings, datasets, validation,
               files: list[tuple[str, Path]], digest: str) -> dict:
    from ..job.run import JobOptions, ReportOptions, calibrate_job, write

    if folder.exists():
        refusal = replace_refusal(folder, "fleet", also=(RECORD,)) if folder.is_dir() else \
            f"{folder} is a file"
        if refusal is not None:
            raise InputError(f"{refusal.split('; ')[0]}; move it away so the robot's result "
                             "can be written there", where=robot.name)
    not_replacing_inputs(folder, [path for _, path in files], option=robot.name)
    result = calibrate_job(datasets, validation,
                           JobOptions(diagnose=settings.diagnose, method=settings.method,
                                      loss=settings.loss, max_iterations=settings.max_iterations,
                                      rule=settings.rule, profile=settings.profile,
                                      fleet_prior=_prior(settings, robot.name)))
    if input_hash(files, settings) != digest:
        raise InputError("its input files changed while it was being calibrated; run again",
                         where=robot.name)
    info = settings.report_info([*datasets, *validation]) if settings.report else None
    templates = None if settings.templates is None else Path(settings.templates)
    outcome = write(result, datasets, validation, folder,
                    ReportOptions(report=settings.report, pdf=settings.pdf, info=info,
                                  templates=templates), verb="fleet")
    summary = robot_summary(outcome.result)
    written = [name for name in outcome.written if not name.startswith(".")]
    record = {"version": RECORD_VERSION, "input_hash": digest, "files": written,
              "summary": summary}
    with atomic_file(folder / RECORD) as staging:
        staging.write_text(json.dumps(record, indent=1) + "\n")
    return summary
