"""Checks of command-line arguments shared by the verbs (not a verb itself).

Output paths are checked before any work is done, so a run that would fail to write
its result fails at once, with one line, instead of after a long computation.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError


def _parent_usable(path: Path, option: str) -> None:
    """The nearest existing ancestor of ``path`` must be a folder (it is created below)."""
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise InputError(f"{parent} is a file, so {path} cannot be created",
                                 where=option)
            return


def output_file(path: str | Path, option: str = "--out") -> Path:
    """A file to write: not an existing folder, and not under a file."""
    path = Path(path)
    if str(path).strip() == "":
        raise InputError("expected a file name", where=option)
    if path.is_dir():
        raise InputError(f"{path} is a folder; expected a file name", where=option)
    _parent_usable(path, option)
    return path


def output_folder(path: str | Path, option: str = "--out") -> Path:
    """A folder to write (replaced as a whole): not an existing file, and not under one."""
    path = Path(path)
    if str(path).strip() == "":
        raise InputError("expected a folder name", where=option)
    if path.exists() and not path.is_dir():
        raise InputError(f"{path} is a file; expected a folder (it is replaced as a whole)",
                         where=option)
    _parent_usable(path, option)
    return path


def input_file(path: str | Path, what: str) -> Path:
    """A file to read: it exists and is not a folder."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"expected a {what}, found a folder", file=path)
    if not path.exists():
        raise InputError(f"{what} not found", file=path)
    return path


def positive_count(value: int, option: str) -> int:
    """A count that must be at least 1."""
    if value < 1:
        raise InputError(f"expected a positive count, got {value}", where=option)
    return value


def not_replacing_inputs(folder: Path, inputs, option: str = "--out") -> None:
    """Refuse an output folder that holds one of the input files: replacing the folder
    as a whole would delete them."""
    try:
        root = Path(folder).resolve()
    except OSError:
        return
    for item in inputs:
        if item is None:
            continue
        try:
            resolved = Path(item).resolve()
        except OSError:
            continue
        if resolved == root or root in resolved.parents:
            raise InputError(f"{folder} holds the input {item}; the output folder is replaced "
                             "as a whole, so choose another one", where=option)
