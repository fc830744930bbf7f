"""The set-up as the planner runs it: the robot within its working joint ranges
(``ranges``), its link capsules (``collision.Body``) and the workspace that checks reach,
limits and clearance (``reach.Workspace``). Every planner and benchmark starts here, so a
plan and the random plans it is compared with obey the same checks."""

from __future__ import annotations

from dataclasses import replace

from robocal_casadi.model.kinematics import Kinematics

from .collision import Body
from .ranges import working_ranges
from .reach import Workspace
from .setup import PlanSetup


def runnable_setup(setup: PlanSetup) -> tuple[PlanSetup, Kinematics, Workspace]:
    """``(setup with working joint ranges, its kinematics, its workspace)``."""
    setup = replace(setup, robot=working_ranges(setup.robot))
    kinematics = Kinematics(setup.robot)
    workspace = Workspace(kinematics, table_height=setup.table_height,
                          body=Body.of(setup, kinematics))
    return setup, kinematics, workspace
