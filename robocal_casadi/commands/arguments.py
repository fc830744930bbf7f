"""Checks of command-line arguments shared by the verbs (not a verb itself).

Output paths are checked before any work is done, so a run that would fail to write
its result, or would destroy something, fails at once, with one line, instead of after
a long computation:

* a file output must be a new name or a regular file (never a device, a pipe or a
  socket, which replacing would destroy), not one of the run's inputs, in a folder
  that can be written (tried: an entry is made there and removed, as permission bits
  alone miss root, /proc and file systems that refuse writes their own way);
* a folder output is replaced as a whole: it must not be the current folder or hold
  it, nor hold or be any file the run reads; when it exists and is not empty, it must be
  a folder the same verb wrote, holding only the files it wrote, unchanged (its marker
  ``.robocal-output`` lists them), unless ``--force`` is given; and a folder holding a
  dataset, job or fleet file the verb did not write there is refused even with
  ``--force`` (``output.replace_refusal``).
"""

from __future__ import annotations

import argparse
import errno
import os
import stat
import tempfile
from pathlib import Path

from ..common.output import not_replacing_inputs, replace_refusal
from ..common.output import resolved_path as _resolved
from ..errors import InputError


def _nearest_existing(path: Path) -> Path | None:
    for parent in path.parents:
        if parent.exists():
            return parent
    return None


def _parent_usable(path: Path, option: str) -> None:
    """The nearest existing ancestor of ``path`` must be a folder we may write in (the
    missing ones are created below it)."""
    parent = _nearest_existing(path)
    if parent is None:
        return
    if not parent.is_dir():
        raise InputError(f"{parent} is a file, so {path} cannot be created", where=option)
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"the folder {parent} is not writable, so {path} cannot be written",
                         where=option)
    # Permission bits do not tell everything (root ignores them; /proc and some network
    # or FUSE file systems refuse new entries all the same): make and remove a probe.
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".robocal-probe-", dir=parent))
    except OSError as error:
        raise InputError(f"the folder {parent} is not writable ({error.strerror or error}), "
                         f"so {path} cannot be written", where=option) from None


def _kind_of(mode: int) -> str:
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISFIFO(mode):
        return "a named pipe"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _same_file(a: Path, b: Path) -> bool:
    """True when ``a`` and ``b`` name the same existing file (also through links)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


def output_file(path: str | Path, option: str = "--out", *, inputs=()) -> Path:
    """A file to write: a new name or an existing regular file that is none of
    ``inputs``, not under a file, in a folder that can be written."""
    path = Path(path)
    if str(path).strip() == "":
        raise InputError("expected a file name", where=option)
    if path.is_dir():
        raise InputError(f"{path} is a folder; expected a file name", where=option)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        mode = None
    except OSError as error:
        raise InputError(f"{path} cannot be used ({error.strerror})", where=option) from None
    if mode is not None and not stat.S_ISREG(mode):
        raise InputError(f"{path} is {_kind_of(mode)}; expected a regular file to write",
                         where=option)
    for item in inputs:
        if item is not None and (_same_file(path, Path(item))
                                 or _resolved(path) == _resolved(Path(item))):
            raise InputError(f"{path} is the input {item}; write the output to another file",
                             where=option)
    _parent_usable(path, option)
    return path


def output_folder(path: str | Path, option: str = "--out", *, verb: str, force: bool = False,
                  inputs=(), keeps: tuple[str, ...] = ()) -> Path:
    """A folder for ``verb`` to write (replaced as a whole): not an existing file, not
    under one, not the current folder or one holding it, holding none of ``inputs``, and
    empty or one ``verb`` wrote (``output.replace_refusal``; ``force`` lifts part of it).
    ``keeps``: names the verb carries over into its new folder, so never lost."""
    path = Path(path)
    if str(path).strip() == "":
        raise InputError("expected a folder name", where=option)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        mode = None
    except OSError as error:
        raise InputError(f"{path} cannot be used ({error.strerror})", where=option) from None
    if mode is not None and not stat.S_ISDIR(mode):
        raise InputError(f"{path} is a file; expected a folder (it is replaced as a whole)",
                         where=option)
    root = _resolved(path)
    here = _resolved(Path.cwd())
    if root == here or root in here.parents or root.parent == root:
        raise InputError(f"{path} is the current folder or holds it; the output folder is "
                         "replaced as a whole, so name a new folder", where=option)
    not_replacing_inputs(path, inputs, option)
    if mode is not None:
        try:
            refusal = replace_refusal(path, verb, force=force, also=keeps)
        except OSError as error:
            raise InputError(f"{path} cannot be read ({error.strerror or error}), so it cannot "
                             "be checked before it is replaced", where=option) from None
        if refusal is not None:
            raise InputError(refusal, where=option)
    _parent_usable(path, option)
    return path


def add_force(parser: argparse.ArgumentParser) -> None:
    """The ``--force`` option of verbs that write a folder."""
    parser.add_argument("--force", action="store_true",
                        help="replace the --out folder even when this verb did not write it "
                        "(its contents are deleted; never a folder holding a dataset or an "
                        "input of the run)")


def add_allow_outside_data(parser: argparse.ArgumentParser) -> None:
    """The ``--allow-outside-data`` option of verbs that read dataset or job files."""
    parser.add_argument("--allow-outside-data", action="store_true",
                        help="let a dataset or job file's data: name a table outside the "
                        "file's own folder tree (an absolute path or ../)")


def input_file(path: str | Path, what: str) -> Path:
    """A file to read: it exists and is not a folder (nor a loop of links)."""
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise InputError(f"{what} not found", file=path) from None
    except OSError as error:
        reason = "a loop of symbolic links" if error.errno == errno.ELOOP else error.strerror
        raise InputError(f"cannot read the {what} ({reason})", file=path) from None
    if stat.S_ISDIR(mode):
        raise InputError(f"expected a {what}, found a folder", file=path)
    return path


def positive_count(value: int, option: str) -> int:
    """A count that must be at least 1."""
    if value < 1:
        raise InputError(f"expected a positive count, got {value}", where=option)
    return value


MAX_SEED = 2**32 - 1


def seed(text: str) -> int:
    """An argparse type: a random seed, a whole number from 0 to 2^32 - 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text[:40]!r}") from None
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"expected a seed from 0 to {MAX_SEED}, got "
                                         f"{text[:40]}")
    return value

