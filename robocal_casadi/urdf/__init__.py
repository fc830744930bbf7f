"""URDF robots: read a serial chain from a URDF file, convert it to DH where the axes
allow, and write a calibrated chain back over the user's own URDF (and UR's calibration
format).

``document`` (the file) and ``description`` (the chain as a robot-file mapping, which
``robot.load_robot`` reads) need nothing of the robot model and are all this package
imports; ``chain`` (file -> ``Robot``), ``equivalent`` (the standard DH equivalent) and
``writer`` (calibrated robot -> URDF, UR kinematics) are imported from their modules.
"""

from .description import chain_description, is_urdf, read_description
from .document import UrdfDocument, read_document

__all__ = ["UrdfDocument", "chain_description", "is_urdf", "read_description",
           "read_document"]
