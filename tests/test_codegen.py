"""Compiled CasADi functions agree with the interpreted ones and are cached on disk."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import warnings

import casadi as ca
import numpy as np
import pytest

from robocal_casadi.common import codegen
from robocal_casadi.model import examples
from robocal_casadi.model.kinematics import Kinematics

needs_compiler = pytest.mark.skipif(codegen.compiler() is None,
                                    reason="no C compiler (cc/gcc) on this machine")


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOCAL_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


@needs_compiler
@pytest.mark.parametrize("robot_name", ["industrial_6r", "prismatic_rrp"])
def test_compiled_agrees_with_interpreted(cache, robot_name):
    kinematics = Kinematics(examples.ROBOTS[robot_name]())
    rng = np.random.default_rng(9)
    p = kinematics.nominal + rng.normal(0, 1e-3, len(kinematics.registry))
    offset = np.array([0.01, 0.02, 0.12])
    with warnings.catch_warnings():
        warnings.simplefilter("error", codegen.CompilationWarning)
        pose = kinematics.compiled("tool_pose")
        jacobians = kinematics.compiled("point_jacobians")
    assert pose.is_a("External") and jacobians.is_a("External")
    assert len(list(cache.glob("*.so"))) == 2
    Q = rng.uniform(-1, 1, (20, kinematics.dof))
    for q in Q:
        np.testing.assert_allclose(np.asarray(pose(q, p)), np.asarray(kinematics.tool_pose(q, p)),
                                   rtol=1e-14, atol=1e-15)
        for mine, reference in zip(jacobians(q, p, offset),
                                   kinematics.point_jacobians(q, p, offset)):
            np.testing.assert_allclose(np.asarray(mine), np.asarray(reference), rtol=1e-14,
                                       atol=1e-15)
    batched = np.asarray(kinematics.mapped(pose, len(Q))(Q.T, p))
    np.testing.assert_allclose(batched.reshape(4, len(Q), 4).transpose(1, 0, 2),
                               kinematics.tool_poses(Q, p), rtol=1e-14, atol=1e-15)


@needs_compiler
def test_library_is_reused_across_instances(cache):
    x = ca.SX.sym("x", 2)
    function = ca.Function("square_sum", [x], [ca.dot(x, x)])
    first = codegen.compiled(function)
    library = next(cache.glob("*.so"))
    stamp = library.stat().st_mtime_ns
    codegen._loaded.clear()  # as in a new process: only the file on disk remains
    second = codegen.compiled(function)
    assert library.stat().st_mtime_ns == stamp and len(list(cache.glob("*.so"))) == 1
    assert float(first([3, 4])) == float(second([3, 4])) == 25.0


def test_without_compiler_falls_back_with_one_warning(cache, monkeypatch):
    monkeypatch.setattr(codegen, "compiler", lambda: None)
    monkeypatch.setattr(codegen, "_warned", set())
    x = ca.SX.sym("x")
    function = ca.Function("twice", [x], [2 * x])
    with pytest.warns(codegen.CompilationWarning, match="no C compiler"):
        assert codegen.compiled(function) is function
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert codegen.compiled(function) is function  # said once only
    assert not cache.exists()


@needs_compiler
def test_compilation_failure_falls_back(cache, monkeypatch):
    monkeypatch.setattr(codegen, "_warned", set())
    monkeypatch.setattr(codegen, "FLAGS", ("-O2", "-shared", "-fPIC", "--no-such-flag"))
    x = ca.SX.sym("x")
    function = ca.Function("thrice", [x], [3 * x])
    with pytest.warns(codegen.CompilationWarning, match="compiling 'thrice' failed"):
        assert codegen.compiled(function) is function
    assert not list(cache.glob("*.so"))


@pytest.mark.parametrize("compile", [pytest.param(True, marks=needs_compiler), False],
                         ids=["compiled", "interpreted"])
@pytest.mark.parametrize("robot_name", ["panda_7dof", "prismatic_rrp"])
def test_batch_function_agrees_row_by_row(cache, robot_name, compile):
    """Hoisted, chunked evaluation equals the plain function on every row (partial chunks too)."""
    kinematics = Kinematics(examples.ROBOTS[robot_name]())
    rng = np.random.default_rng(12)
    p = kinematics.nominal + rng.normal(0, 1e-2, len(kinematics.registry))
    offset = np.array([0.03, -0.01, 0.2])
    Q = rng.uniform(-1, 1, (37, kinematics.dof))
    cases = {"point_jacobians": (offset,), "tool_jacobian": (), "joint_frames": ()}
    for name, shared in cases.items():
        batch = codegen.BatchFunction(getattr(kinematics, name), chunk=16, compile=compile)
        outputs = batch(Q, p, *shared)
        assert len(outputs) == getattr(kinematics, name).n_out()
        for k, q in enumerate(Q):
            expected = getattr(kinematics, name)(q, p, *shared)
            expected = expected if isinstance(expected, (list, tuple)) else [expected]
            for got, want in zip(outputs, expected):
                want = np.asarray(want)
                np.testing.assert_allclose(got[k], want.reshape(got[k].shape), rtol=1e-14,
                                           atol=1e-15)


@needs_compiler
def test_kinematics_batch_is_built_once(cache):
    kinematics = Kinematics(examples.industrial_6r())
    batch = kinematics.batch("tool_pose")
    assert kinematics.batch("tool_pose") is batch and "compiled" in repr(batch)
    Q = np.random.default_rng(13).uniform(-1, 1, (300, kinematics.dof))
    (poses,) = batch(Q, kinematics.nominal)
    np.testing.assert_allclose(poses, kinematics.tool_poses(Q), rtol=1e-14, atol=1e-15)


# ----------------------------------------------------------------------------- a private cache


def _fresh_function(name: str) -> ca.Function:
    x = ca.SX.sym("x", 2)
    return ca.Function(name, [x], [ca.dot(x, x) + 1])


@pytest.fixture
def loose_umask():
    """A umask that would make new files group-writable (002), restored afterwards."""
    previous = os.umask(0o002)
    yield
    os.umask(previous)


@needs_compiler
def test_cache_folder_and_library_are_private_under_any_umask(cache, loose_umask):
    compiled = codegen.compiled(_fresh_function("private_square"))
    assert compiled.is_a("External")
    assert stat.S_IMODE(cache.stat().st_mode) == 0o700
    (library,) = cache.glob("*.so")
    assert not library.stat().st_mode & 0o022


@needs_compiler
def test_a_cache_others_may_write_is_not_used(cache, monkeypatch):
    monkeypatch.setattr(codegen, "_private_warned", set())
    cache.mkdir(mode=0o700)
    cache.chmod(0o777)  # as a shared or carelessly made folder
    with pytest.warns(codegen.CompilationWarning, match="others may write"):
        compiled = codegen.compiled(_fresh_function("shared_cache_square"))
    assert compiled.is_a("External") and float(compiled([1, 2])) == 6.0
    assert not list(cache.glob("*.so"))  # built in a private folder instead


def _compile_in_another_process(cache, *functions: tuple[str, str]) -> None:
    """Compile ``(name, expression in x)`` functions into ``cache`` from a separate
    process, as an earlier run would: this process never maps those libraries, so the
    test may change the files on disk."""
    lines = ["import casadi as ca", "from robocal_casadi.common import codegen",
             "x = ca.SX.sym('x', 2)"]
    for name, expression in functions:
        lines.append(f"assert codegen.compiled(ca.Function({name!r}, [x], [{expression}]))"
                     ".is_a('External')")
    subprocess.run([sys.executable, "-c", "\n".join(lines)], check=True, timeout=300,
                   env={**os.environ, "ROBOCAL_CACHE": str(cache)})


@needs_compiler
def test_a_planted_library_is_never_loaded(cache, monkeypatch):
    """A library under the expected name that others could have written (or that belongs
    to another user) is not run: the function is compiled afresh elsewhere."""
    _compile_in_another_process(cache, ("planted_square", "ca.dot(x, x) + 1"))
    (library,) = cache.glob("*.so")
    # Another function of the same name: its library is what an attacker would plant.
    _compile_in_another_process(cache, ("planted_square", "ca.SX(-1)"))
    (impostor,) = [p for p in cache.glob("*.so") if p != library]
    shutil.copyfile(impostor, library)
    library.chmod(0o666)
    function = _fresh_function("planted_square")
    with pytest.warns(codegen.CompilationWarning, match="another user or others may write"):
        again = codegen.compiled(function)
    assert float(again([1, 2])) == 6.0  # its own code, not the planted one
    if os.geteuid() == 0:  # root can hand the file to another user
        library.chmod(0o700)
        os.chown(library, 65534, 65534)
        codegen._loaded.clear()
        with pytest.warns(codegen.CompilationWarning, match="another user"):
            assert float(codegen.compiled(function)([1, 2])) == 6.0


@needs_compiler
def test_a_truncated_library_is_compiled_again(cache):
    _compile_in_another_process(cache, ("truncated_square", "ca.dot(x, x) + 1"))
    (library,) = cache.glob("*.so")
    size = library.stat().st_size
    with library.open("r+b") as handle:
        handle.truncate(200)  # as a run killed while copying it, or a full disk
    with warnings.catch_warnings():
        warnings.simplefilter("error", codegen.CompilationWarning)
        again = codegen.compiled(_fresh_function("truncated_square"))
    assert again.is_a("External") and float(again([1, 2])) == 6.0
    assert library.stat().st_size == size


@needs_compiler
def test_build_folders_of_killed_runs_are_removed(cache):
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    cache.mkdir(mode=0o700)
    stale = cache / f"robocal_build_{gone.pid}_abc"
    stale.mkdir()
    (stale / "function.c").write_text("int x;")
    live = cache / f"robocal_build_{os.getppid()}_def"
    live.mkdir()
    codegen.compiled(_fresh_function("cleaning_square"))
    assert not stale.exists() and live.is_dir()


@needs_compiler
def test_a_cache_under_a_folder_others_may_write_is_not_used(tmp_path, monkeypatch):
    """A private cache folder inside a world-writable (not sticky) folder could be renamed
    away and replaced by anyone: its libraries are not loaded; the code is built again in a
    private folder, with a warning naming the open folder."""
    shared = tmp_path / "shared"
    cache = shared / "cache"
    monkeypatch.setenv("ROBOCAL_CACHE", str(cache))
    _compile_in_another_process(cache, ("exposed_square", "ca.dot(x, x) + 1"))
    (library,) = cache.glob("*.so")
    monkeypatch.setattr(codegen, "_private_warned", set())
    shared.chmod(0o777)
    try:
        with pytest.warns(codegen.CompilationWarning, match=f"under {shared}, which others"):
            compiled = codegen.compiled(_fresh_function("exposed_square"))
        assert compiled.is_a("External") and float(compiled([1, 2])) == 6.0
        assert (codegen._private_folder() / library.name).is_file()  # built again there
        shared.chmod(0o1777)  # sticky, as /tmp: others cannot move our folder
        assert codegen.exposed_ancestor(cache) is None
    finally:
        shared.chmod(0o700)
    assert library.is_file()


def test_ancestors_are_judged_by_owner_mode_and_sticky_bit(tmp_path):
    folder = tmp_path / "a" / "b"
    folder.mkdir(parents=True)
    assert codegen.exposed_ancestor(folder / "cache") is None
    (tmp_path / "a").chmod(0o775)  # group may write: as open as others for compiled code
    try:
        assert codegen.exposed_ancestor(folder / "cache") == tmp_path / "a"
    finally:
        (tmp_path / "a").chmod(0o755)
    link = tmp_path / "link"
    link.symlink_to(folder)
    (tmp_path / "a").chmod(0o777)
    try:  # the folder reached through a link is judged where it really is
        assert codegen.exposed_ancestor(link / "cache") == tmp_path / "a"
    finally:
        (tmp_path / "a").chmod(0o755)
