"""URDF robots: read a serial chain from a URDF file, convert it to DH where the axes
allow, and write a calibrated chain back over the user's own URDF (and UR's calibration
format).

Reading the file is part of the robot model, since ``model.robot.load_robot`` reads URDF
robots: ``model.urdf_document`` (the file) and ``model.urdf_description`` (the chain as a
robot-file mapping), re-exported here. This package sits above the model: ``chain``
(file -> ``Robot``), ``equivalent`` (the standard DH equivalent) and ``writer``
(calibrated robot -> URDF, UR kinematics) are imported from their modules.
"""

from ..model.urdf_description import chain_description, is_urdf, read_description
from ..model.urdf_document import UrdfDocument, read_document

__all__ = ["UrdfDocument", "chain_description", "is_urdf", "read_description",
           "read_document"]
