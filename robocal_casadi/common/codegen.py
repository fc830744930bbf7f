"""Compiling CasADi functions to machine code, once, and evaluating them over batches.

``compiled(function)`` generates C for ``function``, compiles it with
``cc -O2 -shared -fPIC`` into a cache folder and loads it with ``casadi.external``. The
library is named after a hash of the generated source and the compiler command, so a
function is compiled the first time it is needed and reused from then on, across
processes. Cache folder: ``$ROBOCAL_CACHE`` if set, else ``~/.cache/robocal_casadi``;
compiler: ``$CC`` if set, else ``cc``, else ``gcc``.

Where no compiler is found or compilation fails, the interpreted function is returned
unchanged and a warning says why (once per reason), so callers never depend on a
compiler being present.

A library is machine code run with the caller's rights, so the cache is private: the
folder is created 0700, and a folder or library that belongs to another user or that
others may write is never used, nor a folder under one that others may write (where they
could swap the whole folder): the function is compiled into a private temporary folder
instead, with a warning. A library that does not load (truncated, corrupt) is
compiled again. Build folders of killed runs (``robocal_build_<pid>_*``) are removed
once their process is gone.

Processes sharing the cache (the workers of a fleet calibration) never compile the same
library at once: a compilation holds an exclusive lock on ``<library>.lock`` beside it,
and a process that waited for the lock loads what the other one wrote instead of
compiling it again. The library itself only appears by an atomic rename once complete,
so a reader never sees half a file, with or without the lock.

``BatchFunction`` evaluates a function over many rows (e.g. joint readings) that share
the other inputs (e.g. the parameter vector): whatever depends on the shared inputs
alone (sines and cosines of DH angles, base and tool rotations, ...) is computed once
per chunk of rows, the rest in a compiled loop, reading and writing numpy arrays in
place.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import shutil
import stat
import subprocess
import tempfile
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import casadi as ca
import numpy as np

try:
    import fcntl
except ImportError:  # not POSIX: the atomic rename alone keeps readers safe
    fcntl = None  # type: ignore[assignment]

# No fused multiply-add contraction: the compiled functions round as the interpreted ones do,
# on every processor and compiler default.
FLAGS = ("-O2", "-ffp-contract=off", "-shared", "-fPIC")
_warned: set[str] = set()
_loaded: dict[tuple[str, str], ca.Function] = {}
_private: list[Path] = []  # this process's fallback cache, made on first need
_BUILD = re.compile(r"robocal_build_(?P<pid>\d+)_.*")
STALE_BUILD_AGE = 3600.0  # [s] a build folder this old is abandoned whatever its process


class CompilationWarning(UserWarning):
    """Compiled code is unavailable; the interpreted CasADi function is used instead."""


def cache_folder() -> Path:
    """Where compiled libraries live: ``$ROBOCAL_CACHE`` or ``~/.cache/robocal_casadi``."""
    configured = os.environ.get("ROBOCAL_CACHE")
    if configured:
        return Path(configured).expanduser()
    return Path.home() / ".cache" / "robocal_casadi"


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
    version = ca.__version__  # type: ignore[attr-defined]  # set at import, absent from the stub
    digest = hashlib.sha256("\0".join([version, *command, source]).encode()).hexdigest()
    key = (function.name(), digest)
    if key in _loaded:
        return _loaded[key]
    try:
        folder = safe_cache_folder()
    except OSError as error:
        _warn_once(f"no usable cache folder ({_short(error)})")
        return function
    library = folder / f"{digest[:32]}.so"
    if library.exists() and not _owned_privately(library, folder=False):
        # Never run a library someone else could have written: build our own elsewhere.
        warnings.warn(f"{library} belongs to another user or others may write it; compiling "
                      "into a private temporary folder instead", CompilationWarning,
                      stacklevel=2)
        library = _private_folder() / library.name
    for attempt in range(2):
        if not library.is_file():
            try:
                with _compile_lock(library):
                    if not library.is_file():  # another process may have made it meanwhile
                        _compile(cc, source, library)
            except (OSError, subprocess.SubprocessError) as error:
                _warn_once(f"compiling {function.name()!r} failed ({_short(error)})")
                return function
        try:
            loaded = ca.external(function.name(), str(library))
            break
        except RuntimeError as error:
            if attempt == 0:
                # A truncated or corrupt library (a run killed while writing it, a full
                # disk): remove it and compile it again.
                try:
                    library.unlink()
                except OSError:
                    library = _private_folder() / library.name
                continue
            _warn_once(f"loading {library} failed ({_short(error)})")
            return function
    _loaded[key] = loaded
    return loaded


def _owned_privately(path: Path, *, folder: bool) -> bool:
    """True when ``path`` (followed if a link) is a folder or regular file of ours that
    neither the group nor others may write."""
    try:
        info = path.stat()
    except OSError:
        return False
    kind_ok = stat.S_ISDIR(info.st_mode) if folder else stat.S_ISREG(info.st_mode)
    return kind_ok and info.st_uid == os.getuid() and not info.st_mode & 0o022


def safe_cache_folder() -> Path:
    """The cache folder, created 0700 if missing; if it belongs to another user or others
    may write it, a private temporary folder of this process instead (with a warning)."""
    folder = cache_folder()
    if not folder.exists():
        folder.parent.mkdir(parents=True, exist_ok=True)
        try:
            folder.mkdir(mode=0o700)
        except FileExistsError:
            pass  # made by a concurrent process a moment ago: checked below
        else:
            os.chmod(folder, 0o700)  # whatever the umask
    if not _owned_privately(folder, folder=True):
        problem = (f"the cache folder {folder} belongs to another user or others may write "
                   "it")
    else:
        exposed = exposed_ancestor(folder)
        if exposed is None:
            return folder
        problem = (f"the cache folder {folder} lies under {exposed}, which others may write "
                   "(they could swap the folder and its compiled code)")
    if folder not in _private_warned:
        _private_warned.add(folder)
        warnings.warn(f"{problem}; compiled code goes to a private temporary folder instead "
                      "and is built again (make the folder yours with mode 0700 under folders "
                      "only you or the system may write, or set ROBOCAL_CACHE)",
                      CompilationWarning, stacklevel=3)
    return _private_folder()


def exposed_ancestor(folder: Path) -> Path | None:
    """The first folder above ``folder`` (as given and with links resolved) in which
    someone else could rename or replace entries, or None. A folder is safe when it
    belongs to this user or to root and neither its group nor others may write it, or
    when it is sticky (``/tmp``: others may add entries but not move ours)."""
    folder = Path(os.path.abspath(folder))
    for chain in (folder.parents, folder.resolve().parents):
        for parent in chain:
            try:
                info = parent.stat()
            except OSError:
                return parent
            owner_ok = info.st_uid in (0, os.getuid())
            open_to_others = info.st_mode & 0o022 and not info.st_mode & stat.S_ISVTX
            if not owner_ok or open_to_others:
                return parent
    return None


_private_warned: set[Path] = set()


def _private_folder() -> Path:
    if not _private:
        _private.append(Path(tempfile.mkdtemp(prefix="robocal_cache_")))  # 0700
    return _private[0]


def remove_stale_builds(folder: Path) -> None:
    """Remove build folders in ``folder`` left by killed runs: their process is gone, or
    they are older than an hour (a compilation is given ten minutes)."""
    try:
        entries = list(folder.iterdir())
    except OSError:
        return
    for entry in entries:
        match = _BUILD.fullmatch(entry.name)
        if match is None or not entry.is_dir() or entry.is_symlink():
            continue
        pid = int(match.group("pid"))
        try:
            old = time.time() - entry.stat().st_mtime > STALE_BUILD_AGE
        except OSError:
            continue
        if old or (pid != os.getpid() and not _alive(pid)):
            shutil.rmtree(entry, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


@contextlib.contextmanager
def _compile_lock(library: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``<library>.lock`` (made 0600 on first use) while the
    block runs, so that processes sharing the cache compile one library one at a time.
    Where the file system offers no locks, the block runs unlocked (still safe: the
    library appears by rename; at worst two processes do the same work)."""
    if fcntl is None:
        yield
        return
    library.parent.mkdir(parents=True, exist_ok=True)
    try:
        handle = os.open(library.with_name(library.name + ".lock"),
                         os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o600)
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX)
        except OSError:
            pass  # no lock on this file system: carry on unlocked
        yield
    finally:
        os.close(handle)  # closing releases the lock


def _compile(cc: str, source: str, library: Path) -> None:
    """Compile ``source`` into ``library``; the file appears only once it is complete."""
    library.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_builds(library.parent)
    with tempfile.TemporaryDirectory(prefix=f"robocal_build_{os.getpid()}_",
                                     dir=library.parent) as folder:
        source_path = Path(folder) / "function.c"
        source_path.write_text(source)
        output = Path(folder) / library.name
        result = subprocess.run([cc, *FLAGS, str(source_path), "-o", str(output), "-lm"],
                                capture_output=True, text=True, timeout=600)
        if result.returncode != 0:
            raise subprocess.SubprocessError(result.stderr.strip() or f"exit {result.returncode}")
        os.chmod(output, 0o700)  # never group- or world-writable, whatever the umask
        os.replace(output, library)


def _short(error: BaseException) -> str:
    text = " ".join(str(error).split())
    return text if len(text) < 300 else text[:297] + "..."


# ----------------------------------------------------------------------------- batches


def hoisted_map(function: ca.Function, count: int,
                per_row: tuple[str, ...] = ("q",)) -> ca.Function:
    """``function`` over ``count`` rows, its shared-only subexpressions computed once.

    Inputs named in ``per_row`` take ``count`` columns (one per row); the others are
    shared by all rows and given once. Outputs are dense, the rows side by side
    (``rows x (columns * count)``). Built from an SX ``function`` with CasADi's
    ``extract_parametric``; the result is an MX function ready for ``compiled``.
    """
    names = function.name_in()
    unknown = set(per_row) - set(names)
    if unknown:
        raise ValueError(f"{function.name()!r} has no input(s) {sorted(unknown)}; inputs: {names}")
    symbols = function.sx_in()
    shared = [x for x, n in zip(symbols, names) if n not in per_row]
    varying = [x for x, n in zip(symbols, names) if n in per_row]
    outputs = [ca.densify(y) for y in function.call(symbols)]
    core_outputs, extracted, parametric = ca.extract_parametric(outputs, shared)
    constants = ca.vertcat(*extracted) if extracted else ca.SX(0, 1)
    prepare = ca.Function(f"{function.name()}_shared", shared,
                          [ca.vertcat(*parametric) if extracted else ca.SX(0, 1)])
    core = ca.Function(f"{function.name()}_row", [*varying, constants, *shared], core_outputs)
    reduced = list(range(len(varying), len(varying) + 1 + len(shared)))
    loop = core.map(f"{function.name()}_rows", "serial", count, reduced, [])
    inputs = [ca.MX.sym(n, x.size1(), x.size2() * (count if n in per_row else 1))
              for x, n in zip(symbols, names)]
    shared_inputs = [x for x, n in zip(inputs, names) if n not in per_row]
    results = loop(*[x for x, n in zip(inputs, names) if n in per_row],
                   prepare(*shared_inputs), *shared_inputs)
    batch_outputs = list(results) if isinstance(results, (list, tuple)) else [results]
    return ca.Function(f"{function.name()}_batch{count}", inputs, batch_outputs, names,
                       function.name_out())


class BatchFunction:
    """``function`` evaluated over N rows, compiled, reading and writing numpy arrays.

    ``batch(*inputs)``: an input named in ``per_row`` is an ``N x size`` array (row k for
    row k; e.g. ``Q`` N x dof), the others are given once (e.g. ``p``). Returns one
    array per output, shaped ``N x rows`` for column outputs and ``N x rows x columns``
    otherwise. Rows go through in chunks of ``chunk`` (the compiled size; a shorter last
    chunk is padded). Not thread-safe: one instance holds one set of work buffers.
    """

    def __init__(self, function: ca.Function, per_row: tuple[str, ...] = ("q",),
                 chunk: int = 256, compile: bool = True):
        self.name = function.name()
        self.chunk = chunk
        batched = hoisted_map(function, chunk, per_row)
        self.function = compiled(batched) if compile else batched
        self.per_row = tuple(n in per_row for n in function.name_in())
        self.in_shapes = [(function.size1_in(i), function.size2_in(i))
                          for i in range(function.n_in())]
        self.out_shapes = [(function.size1_out(i), function.size2_out(i))
                           for i in range(function.n_out())]
        self._buffer, self._evaluate = self.function.buffer()
        self._alive: tuple = ()

    def __repr__(self) -> str:
        kind = "compiled" if self.function.is_a("External") else "interpreted"
        return f"BatchFunction({self.name!r}, {kind}, chunk={self.chunk})"

    def __call__(self, *inputs) -> tuple[np.ndarray, ...]:
        if len(inputs) != len(self.in_shapes):
            raise ValueError(f"{self.name}: expected {len(self.in_shapes)} inputs, "
                             f"got {len(inputs)}")
        arrays, count = [], None
        for value, (rows, columns), varying in zip(inputs, self.in_shapes, self.per_row):
            value = np.asarray(value, dtype=float)
            if varying:
                value = np.ascontiguousarray(value.reshape(len(value), rows * columns) if
                                             value.ndim > 1 else value.reshape(-1, rows * columns))
                count = len(value) if count is None else count
                if len(value) != count:
                    raise ValueError(f"{self.name}: per-row inputs have different row counts")
            else:
                # Column-major, as CasADi stores matrices.
                value = np.ascontiguousarray(value.reshape(rows, columns).T).ravel()
            arrays.append(value)
        count = count or 0
        outputs = [np.empty((count, columns, rows)) for rows, columns in self.out_shapes]
        scratch_in: list[np.ndarray] = []
        scratch_out: list[np.ndarray] = []
        for start in range(0, count, self.chunk):
            stop = min(start + self.chunk, count)
            full = stop - start == self.chunk
            if not full:
                scratch_in = [np.zeros((self.chunk, a.shape[1])) if v else a
                              for a, v in zip(arrays, self.per_row)]
                for s_, a, v in zip(scratch_in, arrays, self.per_row):
                    if v:
                        s_[: stop - start] = a[start:stop]
                scratch_out = [np.empty((self.chunk,) + o.shape[1:]) for o in outputs]
            for i, (a, v) in enumerate(zip(arrays, self.per_row)):
                source = (a[start:stop] if full else scratch_in[i]) if v else a
                # casadi's stub asks for a byte size its binding takes from the buffer, and
                # numpy's stubs do not declare ndarray a buffer: the calls are right as written.
                self._buffer.set_arg(i, memoryview(source))  # type: ignore[call-arg, arg-type]
            for i, o in enumerate(outputs):
                result = o[start:stop] if full else scratch_out[i]
                self._buffer.set_res(i, memoryview(result))  # type: ignore[call-arg, arg-type]
            self._evaluate()
            if not full:
                for o, s_ in zip(outputs, scratch_out):
                    o[start:stop] = s_[: stop - start]
        # The buffer keeps raw pointers: hold the inputs and scratch they point to until
        # the next call. The outputs are the caller's (every call points the buffer at new
        # ones before evaluating), so a large result is freed as soon as it is dropped.
        self._alive = (arrays, scratch_in, scratch_out)
        # Each row's block is stored column-major: swap to rows x columns.
        shaped = []
        for o, (_, columns) in zip(outputs, self.out_shapes):
            shaped.append(o[:, 0, :] if columns == 1 else o.transpose(0, 2, 1))
        return tuple(shaped)
