"""URDF robots: read a serial chain from a URDF file, convert it to DH where the axes
allow, and write a calibrated chain back over the user's own URDF (and UR's calibration
format). See ``document`` (the file), ``chain`` (file -> ``Robot``), ``equivalent`` (DH
and modified DH equivalents) and ``writer`` (calibrated robot -> URDF, UR kinematics).
"""

from .chain import frame_of, is_urdf, read_urdf_robot, robot_from_document
from .document import UrdfDocument, read_document
from .equivalent import DhEquivalent, dh_equivalent

__all__ = ["DhEquivalent", "UrdfDocument", "dh_equivalent", "frame_of", "is_urdf", "read_document", "read_urdf_robot",
           "robot_from_document"]
