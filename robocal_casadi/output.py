"""Writing outputs all or nothing, and never over something robocal did not write.

A verb writes into a temporary sibling and moves it into place only when everything
succeeded, so a failure never leaves a half-written folder or file behind. Staging
names carry the writing process's id (``.<name>.robocal-<pid>-<random>``), so the
leftovers of a run that was killed are recognised and removed by the next run that
writes beside them (when their process is gone, or after a day).

Every output folder holds a marker file, ``.robocal-output``: a folder with it was
written by robocal and may be replaced as a whole by the next run; any other non-empty
folder is refused unless the caller forces it (see ``commands.arguments``).

An interruption (Ctrl-C) that a library swallowed (a solver that catches the signal and
carries on) is remembered by ``note_interrupt``; nothing is moved into place after it.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import shutil
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

MARKER = ".robocal-output"
MARKER_TEXT = ("robocal_casadi wrote this folder; a run given it as --out replaces it as a "
               "whole.\n")
STAGING_TAG = "robocal"
STALE_AGE = 24 * 3600.0  # [s] staging left by a live process is removed after a day


_interrupt = {"seen": False}


def note_interrupt() -> None:
    """Remember that the user asked to stop (called from the command line's handler)."""
    _interrupt["seen"] = True


def clear_interrupt() -> None:
    """Forget an earlier interruption (each command-line run starts afresh)."""
    _interrupt["seen"] = False


def interrupted() -> bool:
    """Whether an interruption was noted since the program started."""
    return _interrupt["seen"]


def _check_interrupted() -> None:
    if _interrupt["seen"]:
        raise KeyboardInterrupt


def _staging_prefix(target: Path) -> str:
    return f".{target.name}.{STAGING_TAG}-{os.getpid()}-"


_STAGING = re.compile(rf"\.(?P<name>.+)\.{STAGING_TAG}-(?P<pid>\d+)-[^/]*")


def _process_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True  # someone else's process, or cannot tell: keep its files
    return True


def remove_stale_staging(folder: str | Path, name: str | None = None) -> list[Path]:
    """Remove staging files and folders in ``folder`` left by killed runs (of the output
    ``name`` only, when given): those whose process is gone, or older than a day.
    Returns what was removed."""
    removed: list[Path] = []
    try:
        entries = list(Path(folder).iterdir())
    except OSError:
        return removed
    now = time.time()
    for entry in entries:
        match = _STAGING.fullmatch(entry.name)
        if match is None or (name is not None and match.group("name") != name):
            continue
        try:
            age = now - entry.lstat().st_mtime
        except OSError:
            continue
        if _process_alive(int(match.group("pid"))) and age < STALE_AGE:
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                entry.unlink()
        removed.append(entry)
    return removed


def written_by_robocal(folder: str | Path) -> bool:
    """True when ``folder`` carries the marker robocal writes into its output folders."""
    return (Path(folder) / MARKER).is_file()


@contextlib.contextmanager
def atomic_directory(target: str | Path) -> Iterator[Path]:
    """Yield a fresh temporary folder; on success it replaces ``target`` (with the marker
    file added)."""
    target = Path(os.path.abspath(target))
    if target.name in ("", ".", ".."):
        raise ValueError(f"{target} cannot be replaced as a folder")
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_staging(target.parent, target.name)
    staging = Path(tempfile.mkdtemp(prefix=_staging_prefix(target), dir=target.parent))
    os.chmod(staging, 0o777 & ~_umask())  # mkdtemp makes it private; outputs are not
    try:
        yield staging
        (staging / MARKER).write_text(MARKER_TEXT)
        _check_interrupted()
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    if target.exists():
        backup = Path(tempfile.mkdtemp(prefix=_staging_prefix(target), dir=target.parent))
        backup.rmdir()
        target.rename(backup)
        staging.rename(target)
        shutil.rmtree(backup, ignore_errors=True)
    else:
        staging.rename(target)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_file(target: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; on success it is renamed to ``target``."""
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_staging(target.parent, target.name)
    handle, name = tempfile.mkstemp(prefix=_staging_prefix(target), dir=target.parent)
    os.close(handle)
    staging = Path(name)
    try:
        yield staging
        _check_interrupted()
    except BaseException:
        staging.unlink(missing_ok=True)
        raise
    if staging.exists():
        os.chmod(staging, 0o666 & ~_umask())
    os.replace(staging, target)


def json_safe(value):
    """A JSON-safe copy of ``value``: NaN and infinities become null (JSON has neither)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value
