"""Controller formats: what a calibration or a plan is written as (``registry``).

The built-in formats register in this order, which is the order of their flags and
profiles on the command line: URDF, DH table, UR's kinematics file (models, ``robocal
export``); URScript, KUKA KRL, ABB RAPID (programs, ``robocal plan``). A format written
elsewhere imports ``register`` and the record it needs from here and registers itself
in one line.
"""

from .registry import (
    FORMATS,
    ExportSource,
    Format,
    ModelFormat,
    Profile,
    ProgramFormat,
    model_formats,
    option_name,
    profile_parameters,
    profiles,
    program_formats,
    register,
)

__all__ = ["FORMATS", "ExportSource", "Format", "ModelFormat", "Profile", "ProgramFormat",
           "model_formats", "option_name", "profile_parameters", "profiles",
           "program_formats", "register"]

# Registered on import, in the command line's order (hence not sorted).
from . import urdf_file, dh_table, ur_calibration, urscript, krl, rapid  # noqa: E402, F401, I001
