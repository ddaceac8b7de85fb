"""Robot model as data: URDF loading, link meshes and the kinematic tree (no Qt, no GL)."""

from ocu.model.mesh import MeshData
from ocu.model.tree import Joint, KinematicTree, Mimic, TreeError
from ocu.model.urdf import (
    RobotModel,
    UrdfError,
    default_urdf_path,
    load_urdf,
    parse_urdf,
    profile_urdf_path,
)

__all__ = [
    "Joint",
    "KinematicTree",
    "MeshData",
    "Mimic",
    "RobotModel",
    "TreeError",
    "UrdfError",
    "default_urdf_path",
    "load_urdf",
    "parse_urdf",
    "profile_urdf_path",
]
