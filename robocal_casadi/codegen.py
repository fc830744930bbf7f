"""Compiling CasADi functions to machine code, once, with the system C compiler.

``compiled(function)`` generates C for ``function``, compiles it with
``cc -O2 -shared -fPIC`` into a cache folder and loads it with ``casadi.external``. The
library is named after a hash of the generated source and the compiler command, so a
function is compiled the first time it is needed and reused from then on, across
processes. Cache folder: ``$ROBOCAL_CACHE`` if set, else ``~/.cache/robocal_casadi``;
compiler: ``$CC`` if set, else ``cc``, else ``gcc``.

Where no compiler is found or compilation fails, the interpreted function is returned
unchanged and a warning says why (once per reason), so callers never depend on a
compiler being present.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import casadi as ca

FLAGS = ("-O2", "-shared", "-fPIC")
_warned: set[str] = set()
_loaded: dict[tuple[str, str], ca.Function] = {}


class CompilationWarning(UserWarning):
    """Compiled code is unavailable; the interpreted CasADi function is used instead."""


def cache_folder() -> Path:
    """Where compiled libraries live: ``$ROBOCAL_CACHE`` or ``~/.cache/robocal_casadi``."""
    configured = os.environ.get("ROBOCAL_CACHE")
    return Path(configured).expanduser() if configured else Path.home() / ".cache" / "robocal_casadi"


def compiler() -> str | None:
    """The C compiler to use (``$CC``, ``cc`` or ``gcc``), or None when there is none."""
    for candidate in (os.environ.get("CC"), "cc", "gcc"):
        if candidate and shutil.which(candidate):
            return shutil.which(candidate)
    return None


def _warn_once(reason: str) -> None:
    if reason not in _warned:
        _warned.add(reason)
        warnings.warn(f"using interpreted CasADi functions: {reason}", CompilationWarning,
                      stacklevel=3)


def generated_source(function: ca.Function) -> str:
    """The C source CasADi generates for ``function`` (self-contained, no header)."""
    with tempfile.TemporaryDirectory(prefix="robocal_codegen_") as folder:
        generator = ca.CodeGenerator(f"{function.name()}.c", {"with_header": False})
        generator.add(function)
        generator.generate(folder + os.sep)
        return (Path(folder) / f"{function.name()}.c").read_text()


def compiled(function: ca.Function) -> ca.Function:
    """``function`` as compiled code (same name, inputs and outputs), or itself on failure.

    Compilation happens at most once per distinct generated source and compiler command;
    later calls (in this or any process) load the cached shared library.
    """
    cc = compiler()
    if cc is None:
        _warn_once("no C compiler found (set CC, or install cc/gcc)")
        return function
    try:
        source = generated_source(function)
    except RuntimeError as error:
        _warn_once(f"CasADi cannot generate C for {function.name()!r} ({error})")
        return function
    command = (Path(cc).name, *FLAGS)
    digest = hashlib.sha256("\0".join([ca.__version__, *command, source]).encode()).hexdigest()
    key = (function.name(), digest)
    if key in _loaded:
        return _loaded[key]
    folder = cache_folder()
    library = folder / f"{digest[:32]}.so"
    if not library.is_file():
        try:
            _compile(cc, source, library)
        except (OSError, subprocess.SubprocessError) as error:
            _warn_once(f"compiling {function.name()!r} failed ({_short(error)})")
            return function
    try:
        loaded = ca.external(function.name(), str(library))
    except RuntimeError as error:
        _warn_once(f"loading {library} failed ({_short(error)})")
        return function
    _loaded[key] = loaded
    return loaded


def _compile(cc: str, source: str, library: Path) -> None:
    """Compile ``source`` into ``library``; the file appears only once it is complete."""
    library.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="robocal_build_", dir=library.parent) as folder:
        source_path = Path(folder) / "function.c"
        source_path.write_text(source)
        output = Path(folder) / library.name
        result = subprocess.run([cc, *FLAGS, str(source_path), "-o", str(output), "-lm"],
                                capture_output=True, text=True, timeout=600)
        if result.returncode != 0:
            raise subprocess.SubprocessError(result.stderr.strip() or f"exit {result.returncode}")
        os.replace(output, library)


def _short(error: BaseException) -> str:
    text = " ".join(str(error).split())
    return text if len(text) < 300 else text[:297] + "..."
