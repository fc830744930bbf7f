"""Stage progress: shown on a terminal (driven through a pseudo-terminal), silent when piped."""

from __future__ import annotations

import io
import os
import pty
import re
import select
import subprocess
import sys
import time
from pathlib import Path

import pytest

from robocal_casadi.common.progress import Stages, reports_stages, stage
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import industrial_6r

ROOT = Path(__file__).resolve().parents[1]


def test_stages_show_names_and_elapsed_time_and_a_line_for_long_ones(monkeypatch) -> None:
    monkeypatch.setattr("robocal_casadi.common.progress.KEEP_AFTER", 0.0)
    stream = io.StringIO()
    stages = Stages(stream=stream, force=True)
    with stages.stage("identification"):
        with stages.stage("refit"):
            stages.note("2/5")
    text = stream.getvalue()
    assert "identification > refit 2/5 (" in text
    assert re.search(r"\ridentification: \d+\.\d s\n", text.replace("\033[K", ""))


def test_disabled_or_not_a_terminal_writes_nothing() -> None:
    for stages in (Stages(False, stream=io.StringIO(), force=True), Stages(stream=io.StringIO())):
        with stages.stage("identification"):
            stages.note("1/2")
        assert stages.stream.getvalue() == ""


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_job_inside_a_job_reports_on_the_outer_line(monkeypatch) -> None:
    @reports_stages(default=True)
    def inner(*, progress: bool = True) -> None:
        with stage("inner"):
            pass

    @reports_stages(default=False)
    def outer(*, progress: bool = False) -> None:
        with stage("outer"):
            inner()
            inner(progress=False)  # silenced

    for progress, expected in ((True, 1), (False, 0)):
        terminal = _Terminal()
        monkeypatch.setattr(sys, "stderr", terminal)
        outer(progress=progress)
        assert terminal.getvalue().count("outer > inner (") == expected
        assert ("outer (" in terminal.getvalue()) == progress


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("progress")
    return simulate(industrial_6r(), "tracker_points", out_dir=folder / "fit", rows=120,
                    noise=1e-5, geometric_errors=(0.3e-3, 0.3e-3), seed=3,
                    progress=False).dataset_path


def _command(dataset: Path, out: Path) -> list[str]:
    return [sys.executable, "-m", "robocal_casadi.cli", "calibrate", str(dataset), "--out",
            str(out), "--no-report"]


def _environment() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}


def _through_terminal(command: list[str], timeout: float = 300.0) -> tuple[int, str]:
    """Run ``command`` with standard error on a pseudo-terminal; its exit status and what
    it wrote there."""
    leader, follower = pty.openpty()
    process = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                               stderr=follower, env=_environment(), cwd=ROOT)
    os.close(follower)
    chunks = []
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([leader], [], [], 1.0)
            if ready:
                try:
                    data = os.read(leader, 4096)
                except OSError:  # the other end closed: the process is done
                    break
                if not data:
                    break
                chunks.append(data)
            elif process.poll() is not None:
                break
    finally:
        os.close(leader)
    return process.wait(timeout=60), b"".join(chunks).decode(errors="replace")


def test_calibrate_shows_its_stages_on_a_terminal(dataset, tmp_path) -> None:
    status, text = _through_terminal(_command(dataset, tmp_path / "out"))
    assert status == 0, text
    for name in ("nominal fit", "identifiability", "identification", "diagnosis round 1",
                 "screening", "unexplained test"):
        assert f"\r\033[K{name}" in text or f" > {name}" in text, name
    assert " s)" in text  # the elapsed time of the running stage


def test_calibrate_is_silent_when_piped(dataset, tmp_path) -> None:
    done = subprocess.run(_command(dataset, tmp_path / "out") + ["--no-diagnose"],
                          capture_output=True, text=True,
                          env=_environment(), cwd=ROOT, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    assert "\r" not in done.stderr and "identification" not in done.stderr
