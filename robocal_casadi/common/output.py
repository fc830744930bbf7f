"""Writing outputs all or nothing, and never over something robocal did not write.

A verb writes into a temporary sibling and moves it into place only when everything
succeeded, so a failure never leaves a half-written folder or file behind. Staging
names carry the writing process's id (``.<name>.robocal-<pid>-<random>``), so the
leftovers of a run that was killed are recognised and removed by the next run that
writes beside them (when their process is gone, or after a day).

Every output folder holds a marker file, ``.robocal-output``, naming the verb that wrote
it and every file it wrote with its SHA-256. A later run of the same verb may replace the
folder as a whole only while it holds exactly those files, unchanged
(``replace_refusal``); a folder another verb wrote (a simulated dataset given to
calibrate), or one holding anything else, is refused unless the caller forces it, and a
folder holding a dataset or job file robocal did not write there in the same verb is
refused even then (see ``commands.arguments``).

An interruption (Ctrl-C) that a library swallowed (a solver that catches the signal and
carries on) is remembered by ``note_interrupt``; nothing is moved into place after it.
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import os
import re
import shutil
import tempfile
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

MARKER = ".robocal-output"
MARKER_TEXT = ("robocal_casadi wrote this folder; a later run of the same verb given it as "
               "--out replaces it as a whole while it holds only the files listed here, "
               "unchanged.\n")
MAX_ENTRIES = 10_000  # files looked at before a folder is judged too large to replace
DATASET_KEYS = ("kind", "robots")  # top-level keys of dataset, job and fleet files
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


@dataclass(frozen=True)
class Marker:
    """What a marker file says: the verb that wrote the folder (None for a marker of an
    earlier version, which did not say) and each file it wrote (path relative to the
    folder -> SHA-256 of its content)."""

    verb: str | None
    files: Mapping[str, str] = field(default_factory=dict)

    def text(self) -> str:
        lines = [MARKER_TEXT, f"verb: {self.verb}\n"] if self.verb else [MARKER_TEXT]
        lines += [f"file: {digest} {name}\n" for name, digest in sorted(self.files.items())]
        return "".join(lines)


def read_marker(folder: str | Path) -> Marker | None:
    """The marker of ``folder``, or None when it has none (or it cannot be read)."""
    try:
        text = (Path(folder) / MARKER).read_text(errors="replace")
    except OSError:
        return None
    verb, files = None, {}
    for line in text.splitlines():
        key, _, value = line.partition(": ")
        if key == "verb":
            verb = value.strip()
        elif key == "file":
            digest, _, name = value.partition(" ")
            files[name] = digest
    return Marker(verb, files)


def _digest(path: Path) -> str:
    """SHA-256 of a file's content (of the target's name for a symbolic link)."""
    if path.is_symlink():
        return "link-" + hashlib.sha256(os.readlink(path).encode()).hexdigest()
    sha = hashlib.sha256()
    with path.open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            sha.update(block)
    return sha.hexdigest()


def folder_files(folder: Path, *, limit: int = MAX_ENTRIES) -> dict[str, str] | None:
    """Every file under ``folder`` (relative posix path -> SHA-256), leaving out the marker
    and the staging leftovers of killed runs; None when there are more than ``limit``.
    Raises OSError when a part of it cannot be read."""
    found: dict[str, str] = {}
    count = 0

    def unreadable(error: OSError) -> None:
        raise error

    for top, dirs, files in os.walk(folder, onerror=unreadable):
        dirs[:] = [d for d in dirs if not _STAGING.fullmatch(d)]
        for name in (*files, *(d for d in dirs if os.path.islink(os.path.join(top, d)))):
            count += 1
            if count > limit:
                return None
            path = Path(top) / name
            relative = path.relative_to(folder).as_posix()
            if relative == MARKER or _STAGING.fullmatch(name):
                continue
            found[relative] = _digest(path)
    return found


def _is_dataset_file(path: Path) -> bool:
    """True for a YAML file whose top level names a dataset's or job's ``kind`` or a
    fleet's ``robots`` (read from its first 64 KiB, without parsing it)."""
    if path.suffix.lower() not in (".yaml", ".yml") or path.is_symlink():
        return False
    try:
        with path.open("rb") as handle:
            head = handle.read(1 << 16).decode("utf-8", errors="replace")
    except OSError:
        return False
    return any(re.match(rf"({'|'.join(DATASET_KEYS)})\s*:", line) for line in head.splitlines())


def replace_refusal(folder: str | Path, verb: str, *, force: bool = False,
                    also: tuple[str, ...] = ()) -> str | None:
    """Why ``verb`` must not replace the existing folder ``folder`` as a whole, or None
    when it may. ``also``: file names the verb writes into the folder after its marker.

    Refused, even with ``force``: a dataset, job or fleet file that is not one ``verb``
    wrote there. Refused without ``force``: a folder with no marker and something in it,
    a marker of another verb (or of none), a file the marker does not list, a listed file
    changed since, or more files than can be checked."""
    folder = Path(folder)
    marker = read_marker(folder)
    files = folder_files(folder)
    if files is None:
        return (f"{folder} holds more than {MAX_ENTRIES} files; robocal did not write it as "
                "one output, so name a new folder")
    ours = dict(marker.files) if marker is not None and marker.verb == verb else {}
    datasets = sorted(n for n, d in files.items()
                      if ours.get(n) != d and _is_dataset_file(folder / n))
    if datasets:
        return (f"{folder} holds the dataset or job file {datasets[0]}, which this verb did "
                "not write there; robocal never replaces such a folder, so name a new one")
    if force or not files:
        return None
    if marker is None:
        return (f"{folder} is a folder robocal did not write and it is not empty; the output "
                "folder is replaced as a whole, so name a new folder (or give --force to "
                "replace it)")
    if marker.verb != verb:
        by = f"robocal {marker.verb}" if marker.verb else "an earlier robocal version"
        return (f"{folder} was written by {by}, not robocal {verb}; name a new folder (or give "
                "--force to replace it)")
    foreign = sorted(n for n, d in files.items()
                     if n not in also and ours.get(n) != d)
    if foreign:
        what = "changed since robocal wrote it" if foreign[0] in ours else "not written by robocal"
        more = f" (and {len(foreign) - 1} more)" if len(foreign) > 1 else ""
        return (f"{folder} holds {foreign[0]}{more}, {what}; the output folder is replaced as a "
                "whole, so name a new folder (or give --force to replace it)")
    return None


@contextlib.contextmanager
def atomic_directory(target: str | Path, *, verb: str) -> Iterator[Path]:
    """Yield a fresh temporary folder; on success it replaces ``target``, with the marker
    file added (naming ``verb`` and every file written)."""
    target = Path(os.path.abspath(target))
    if target.name in ("", ".", ".."):
        raise ValueError(f"{target} cannot be replaced as a folder")
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_staging(target.parent, target.name)
    staging = Path(tempfile.mkdtemp(prefix=_staging_prefix(target), dir=target.parent))
    os.chmod(staging, 0o777 & ~_umask())  # mkdtemp makes it private; outputs are not
    try:
        yield staging
        (staging / MARKER).write_text(Marker(verb, folder_files(staging) or {}).text())
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


def resolved_path(path: Path) -> Path:
    """``path`` with links resolved; as written (absolute) where that fails."""
    try:
        return path.resolve()
    except (OSError, RuntimeError):  # a symlink loop: compare the names as written
        return Path(os.path.abspath(path))


def not_replacing_inputs(folder: Path, inputs, option: str = "--out") -> None:
    """Refuse an output folder that is, or holds, one of the inputs (files or folders the
    run reads): replacing the folder as a whole would delete them."""
    from ..errors import InputError

    root = resolved_path(Path(folder))
    for item in inputs:
        if item is None:
            continue
        resolved = resolved_path(Path(item))
        if resolved == root or root in resolved.parents:
            raise InputError(f"{folder} holds the input {item}; the output folder is replaced "
                             "as a whole, so choose another one", where=option)
