"""Experiment design: choosing measurement poses before data is taken
(docs/methods.md#experiment-design).

``design_plan(dataset, count, index)`` draws feasible candidates (bar or artifact
placements, laser poses, tracker configurations), picks ``count`` of them that make the
column-scaled identification Jacobian best for an observability index (greedy start,
exchanges, continuous refinement in CasADi), and compares the result with random
feasible plans of the same size. ``write_plan`` writes it as the dataset's data table.
"""

from .candidates import Candidate, generate
from .design import Plan, design_plan
from .indices import INDICES, canonical, index_of_jacobian, index_value, maximise
from .plan_table import write_plan
from .planned import engine_identifiability, planned_dataset
from .reach import Workspace
from .setup import PlanSetup, setup_from_dataset

__all__ = ["Candidate", "INDICES", "Plan", "PlanSetup", "Workspace", "canonical", "design_plan",
           "engine_identifiability", "generate", "index_of_jacobian", "index_value", "maximise",
           "planned_dataset", "setup_from_dataset", "write_plan"]
