"""The fleet file (FLEET.yaml): which robots to calibrate, from which datasets.

```yaml
robots:
  - name: cell3-r1                   # also the name of its output folder DIR/<name>/
    datasets: [cell3/r1/tracker.yaml]
    validate: [cell3/r1/check.yaml]  # optional held-out datasets
```

Paths are relative to the fleet file's folder (absolute paths are kept). The datasets are
the files ``robocal calibrate`` reads. The fleet file is read strictly: unknown keys,
missing or empty lists, a name that is no plain folder name, names used twice (also when
they differ only in case), and a dataset given twice to one robot are refused with one
line naming the file and the key. Whether the dataset files themselves are good is each
robot's own business: a bad one fails that robot only.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..common.fields import check_keys, cut, file_name, load_yaml, mapping, require
from ..errors import InputError

TOP_KEYS = ("robots",)
ROBOT_KEYS = ("name", "datasets", "validate")
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}")
RESERVED = ("fleet.json", "fleet.html")  # the fleet's own files in DIR


@dataclass(frozen=True)
class FleetRobot:
    """One robot of the fleet: its ``name`` (its output folder), the ``datasets`` to
    calibrate from and the held-out ``validate`` datasets (paths as resolved from the
    fleet file's folder)."""

    name: str
    datasets: tuple[Path, ...]
    validate: tuple[Path, ...] = ()


@dataclass(frozen=True)
class Fleet:
    """The robots a fleet file lists, in its order."""

    path: Path
    robots: tuple[FleetRobot, ...]

    def __repr__(self) -> str:
        return f"Fleet({self.path}, {len(self.robots)} robots)"


def _names(value: Any, *, file: Path, where: str, required: bool) -> tuple[Path, ...]:
    """A list of file names (or one name) under ``where``, resolved from ``file``'s folder."""
    if value is None and not required:
        return ()
    items = [value] if isinstance(value, str) else value
    if not isinstance(items, list) or (required and not items):
        raise InputError(f"expected a list of dataset files, got {cut(value)}", file=file,
                         where=where)
    return tuple(file.parent / file_name(item, file=file, where=f"{where}[{k}]")
                 for k, item in enumerate(items))


def load_fleet(path: str | Path) -> Fleet:
    """Read and check a fleet file; every problem is an ``InputError`` naming the file
    and the key (``robots[3].name``)."""
    path = Path(path)
    content = load_yaml(path, what="fleet file")
    check_keys(content, TOP_KEYS, file=path)
    robots = require(content, "robots", file=path)
    if not isinstance(robots, list) or not robots:
        raise InputError(f"expected a list of robots, got {cut(robots)}", file=path,
                         where="robots")
    out: list[FleetRobot] = []
    seen: dict[str, str] = {}
    for k, raw in enumerate(robots):
        where = f"robots[{k}]"
        entry = mapping(raw, file=path, where=where, hint="with name and datasets")
        check_keys(entry, ROBOT_KEYS, file=path, where=where)
        name = require(entry, "name", file=path, where=where)
        if not isinstance(name, str) or not NAME.fullmatch(name) or name.lower() in RESERVED:
            raise InputError(f"expected a folder name (letters, digits, '.', '_', '-', starting "
                             f"with a letter or digit, at most 100 characters; not "
                             f"{' or '.join(RESERVED)}), got {cut(name)}", file=path,
                             where=f"{where}.name")
        if name.lower() in seen:
            raise InputError(f"the name {name!r} is used twice (also by {seen[name.lower()]}); "
                             "each robot has its own output folder", file=path,
                             where=f"{where}.name")
        seen[name.lower()] = where
        datasets = _names(require(entry, "datasets", file=path, where=where), file=path,
                          where=f"{where}.datasets", required=True)
        validate = _names(entry.get("validate"), file=path, where=f"{where}.validate",
                          required=False)
        given: dict[Path, str] = {}
        for key, files in (("datasets", datasets), ("validate", validate)):
            for j, item in enumerate(files):
                resolved = item.resolve()
                if resolved in given:
                    raise InputError(f"{item} is given twice (also as {given[resolved]}); a "
                                     "dataset is either fitted or held out, once", file=path,
                                     where=f"{where}.{key}[{j}]")
                given[resolved] = f"{key}[{j}]"
        out.append(FleetRobot(name=name, datasets=datasets, validate=validate))
    return Fleet(path=path, robots=tuple(out))
