"""The optimal approximate design against a closed form, and as a bound on exact plans;
refinement of a tracker plan that keeps every reading visible."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import yaml

from planning import design_plan
from planning.approximate import optimal_approximate
from planning.candidates import Candidate, visible
from planning.information import Information
from planning.refine import _rebuild
from planning.rows import Block
from planning.runnable import runnable_setup
from planning.setup import setup_from_dataset
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.model.examples import industrial_6r
from robocal_casadi.model.robot import save_robot


def test_quadratic_regression_gets_the_known_a_optimal_design():
    # y = a + b x + c x^2 on [-1, 1], every coefficient weighed alike (W = I): the
    # A-optimal design puts 1/4 at each end and 1/2 at the centre, trace(M^-1) = 8
    x = np.linspace(-1.0, 1.0, 41)
    blocks = [Block(np.array([[1.0, v, v * v]])) for v in x]
    info = Information(blocks, ("a", "b", "c"), 0, np.eye(3))
    design = optimal_approximate(info, iterations=20000, settled=1.0001)
    w = design.weights
    # the multiplicative algorithm moves weight off the centre's neighbours slowly
    assert w[0] == pytest.approx(0.25, abs=2e-3) and w[-1] == pytest.approx(0.25, abs=2e-3)
    assert w[np.abs(x) < 0.2].sum() == pytest.approx(0.5, abs=2e-3)
    assert w[(np.abs(x) >= 0.2) & (np.abs(x) < 1.0)].sum() < 1e-3
    assert design.lower <= 8.0 <= design.value
    assert design.value == pytest.approx(8.0, rel=1e-3)


@pytest.fixture(scope="module")
def tracker(tmp_path_factory):
    folder = tmp_path_factory.mktemp("approximate")
    save_robot(industrial_6r(), folder / "r6.yaml")
    content = dict(kind="tracker_points", robot="r6.yaml", units=dict(length="mm", angle="deg"),
                   target=dict(xyz=[0, 0, 100]), instrument=dict(xyz=[2500, 0, 800]),
                   data="none.csv")
    (folder / "tracker.yaml").write_text(yaml.safe_dump(content))
    return load_dataset(folder / "tracker.yaml", require_data=False)


def test_no_plan_from_the_pool_predicts_below_the_bound(tracker):
    plan = design_plan(tracker, 20, seed=4, pool=120, refine=False, quiet=True)
    assert np.isfinite(plan.tool_error_bound) and plan.tool_error_bound > 0
    assert plan.tool_error >= plan.tool_error_bound
    assert np.all(plan.random_tool_errors >= plan.tool_error_bound)
    # an exchange search from a greedy start ends close to the bound (within 15%)
    assert plan.tool_error <= 1.15 * plan.tool_error_bound


def test_a_reading_the_solver_left_unrunnable_keeps_its_start(tracker):
    setup, kin, workspace = runnable_setup(setup_from_dataset(tracker))
    plan = design_plan(tracker, 12, seed=5, pool=60, refine=False, quiet=True)

    def turned(candidate, angle):
        joints = candidate.joints.copy()
        joints[0, 0] += angle
        return joints

    def hidden(joints):
        joints = np.clip(joints, workspace.lower, workspace.upper)
        return not visible(setup, kin.flange_poses(joints, workspace.p)).all()

    # a reading whose base turn by half a turn, and by a quarter (the half-way retry),
    # both face the reflector away from the tracker
    away = next(c for c in plan.candidates
                if hidden(turned(c, np.pi)) and hidden(turned(c, np.pi / 2)))
    candidates = [c for c in plan.candidates if c is not away][:2] + [away]
    moved = [c.joints + 0.01 for c in candidates]
    moved[2] = turned(away, np.pi)
    rebuilt = _rebuild(setup, workspace, candidates, moved)
    assert rebuilt is not None
    poses = kin.flange_poses(np.vstack([c.joints for c in rebuilt]), workspace.p)
    assert visible(setup, poses).all()
    assert rebuilt[2] is candidates[2]
    for k in (0, 1):
        if rebuilt[k] is not candidates[k]:
            assert np.allclose(rebuilt[k].joints, moved[k])
    assert isinstance(rebuilt[0], Candidate)


def test_a_plan_predicted_worse_than_random_says_so(tracker):
    plan = design_plan(tracker, 16, seed=6, pool=80, refine=False, quiet=True)
    assert plan.tool_error < plan.random_tool_median
    assert plan.warning == "" and "warning" not in plan.summary()
    worse = replace(plan, tool_error=3.0 * plan.random_tool_median)
    assert "3 times less accurately than the median random plan" in worse.summary()


def test_exchange_progress_says_which_start_and_which_pass():
    """Every progress note of an exchange search names its start (the count of the line)
    and its own pass number, so several starts do not read as the same pass repeated."""
    from planning.selection import exchange

    x = np.linspace(-1.0, 1.0, 41)
    info = Information([Block(np.array([[1.0, v, v * v]])) for v in x], ("a", "b", "c"), 0,
                       np.eye(3))

    class Recorder:
        def __init__(self):
            self.notes: list[tuple[int, str]] = []

        def update(self, done: int, note: str = "") -> None:
            self.notes.append((done, note))

    seen = Recorder()
    for start, initial in enumerate(([18, 19, 20, 21], [0, 1, 2, 3]), start=1):
        exchange(info, initial, "O1", progress=seen, start=start)
    assert {done for done, _ in seen.notes} == {1, 2}
    for start in (1, 2):
        passes = [note.split()[1] for done, note in seen.notes if done == start]
        assert passes == [str(k) for k in range(1, len(passes) + 1)] and len(passes) >= 2
        assert all(note.startswith("pass ") and "swaps" in note for _, note in seen.notes)
