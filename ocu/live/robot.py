"""The robot's own channels on a live server: its URDF, the transforms of its whole tree and
its range scans, as ROS 2 messages (the recorder's channels come from ocu.record.convert).

`/tf_static` carries every fixed joint once, `/tf` every moving joint (mimic joints included)
per telemetry packet, `/robot_description` the URDF text (std_msgs/msg/String), `/scan` a
range scan in the frame `range_sensor`, placed on the URDF's root by the profile's
`scan_mount_xy_m` (a static transform).

A client cannot resolve the URDF's mesh paths (relative to the file, or package:// on this
machine): the served URDF names each mesh `package://ocu_robot/...` and the server hands out
exactly those files through the protocol's fetchAsset (`assets`); nothing else on disk.
"""

from __future__ import annotations

import logging
import math
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np

from ocu.link.diagnostics import DiagnosticReport
from ocu.model.mesh_files import MeshSkippedError, find_mesh_file
from ocu.model.tree import KinematicTree
from ocu.model.urdf import UrdfError, load_urdf, profile_urdf_path
from ocu.profile import RobotProfile
from ocu.record import schemas as s
from ocu.records import ScanFrame

log = logging.getLogger("ocu.live")

TF: Final = "/tf"
TF_STATIC: Final = "/tf_static"
ROBOT_DESCRIPTION: Final = "/robot_description"
SCAN: Final = "/scan"
SCAN_FRAME: Final = "range_sensor"
ASSET_PACKAGE: Final = "package://ocu_robot/"
_MESH_FILENAME = re.compile(r"""(<mesh\b[^>]*?\bfilename\s*=\s*)(["'])(.*?)\2""", re.DOTALL)

_TIME = "int32 sec\nuint32 nanosec\n"
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"

TF_MESSAGE = s.MessageType(
    "tf2_msgs/msg/TFMessage",
    s.concatenate(
        "geometry_msgs/TransformStamped[] transforms\n",
        (
            "geometry_msgs/TransformStamped",
            "std_msgs/Header header\nstring child_frame_id\nTransform transform\n",
        ),
        ("geometry_msgs/Transform", "Vector3 translation\nQuaternion rotation\n"),
        ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
        ("geometry_msgs/Quaternion", "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"),
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
    ),
)

STRING = s.MessageType("std_msgs/msg/String", "string data\n")

DIAGNOSTICS: Final = "/diagnostics"
DIAGNOSTIC_ARRAY = s.MessageType(
    "diagnostic_msgs/msg/DiagnosticArray",
    s.concatenate(
        "std_msgs/Header header\nDiagnosticStatus[] status\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
        (
            "diagnostic_msgs/DiagnosticStatus",
            "byte level\nstring name\nstring message\nstring hardware_id\nKeyValue[] values\n",
        ),
        ("diagnostic_msgs/KeyValue", "string key\nstring value\n"),
    ),
)

LASER_SCAN = s.MessageType(
    "sensor_msgs/msg/LaserScan",
    s.concatenate(
        "std_msgs/Header header\n"
        "float32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n"
        "float32 time_increment\nfloat32 scan_time\n"
        "float32 range_min\nfloat32 range_max\n"
        "float32[] ranges\nfloat32[] intensities\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
    ),
)


def quaternion_xyzw(matrix: np.ndarray[Any, Any]) -> tuple[float, float, float, float]:
    """A rotation (the upper 3x3 of a transform) as a unit quaternion (x, y, z, w), w >= 0."""
    r = matrix[:3, :3]
    w = math.sqrt(max(0.0, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2.0
    x = math.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2])) / 2.0
    y = math.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2])) / 2.0
    z = math.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2])) / 2.0
    return (
        math.copysign(x, r[2, 1] - r[1, 2]),
        math.copysign(y, r[0, 2] - r[2, 0]),
        math.copysign(z, r[1, 0] - r[0, 1]),
        w,
    )


def _transform(
    parent: str, child: str, matrix: np.ndarray[Any, Any], stamp: dict[str, int]
) -> dict[str, Any]:
    x, y, z, w = quaternion_xyzw(matrix)
    return {
        "header": {"stamp": stamp, "frame_id": parent},
        "child_frame_id": child,
        "transform": {
            "translation": {
                "x": float(matrix[0, 3]),
                "y": float(matrix[1, 3]),
                "z": float(matrix[2, 3]),
            },
            "rotation": {"x": x, "y": y, "z": z, "w": w},
        },
    }


@dataclass(frozen=True)
class RobotFrames:
    """The URDF's tree and text; None from `load` when the URDF cannot be read."""

    tree: KinematicTree
    urdf_text: str
    scan_mount_xy_m: tuple[float, float] | None
    # The served URI of each mesh file the URDF names (urdf_text names them so).
    assets: Mapping[str, Path]

    @classmethod
    def load(cls, profile: RobotProfile) -> RobotFrames | None:
        """The profile's URDF (kinematics only, no meshes); None, logged, if unreadable."""
        path = Path(profile_urdf_path(profile))
        try:
            text = path.read_text(encoding="utf-8-sig")
            model = load_urdf(path, meshes=False)
        except (OSError, UnicodeDecodeError, UrdfError) as err:
            log.warning("live: no /tf and /robot_description: %s", err)
            return None
        navigation = profile.navigation
        mount = navigation.scan_mount_xy_m if navigation.footprint is not None else None
        served, assets = serve_meshes(text, path.parent)
        return cls(model.tree, served, mount, assets)

    def _moving(self) -> list[str]:
        return [name for name, joint in self.tree.joints.items() if joint.type != "fixed"]

    def static_message(self, stamp: dict[str, int]) -> dict[str, Any]:
        """/tf_static: every fixed joint, and the range sensor's mount."""
        tree = self.tree
        transforms = [
            _transform(joint.parent, joint.child, joint.origin, stamp)
            for joint in tree.joints.values()
            if joint.type == "fixed"
        ]
        if self.scan_mount_xy_m is not None:
            mount = np.eye(4)
            mount[0, 3], mount[1, 3] = self.scan_mount_xy_m
            transforms.append(_transform(tree.root, SCAN_FRAME, mount, stamp))
        return {"transforms": transforms}

    def moving_message(
        self, positions: Mapping[str, float], stamp: dict[str, int]
    ) -> dict[str, Any]:
        """/tf: every moving joint at these positions (joints not given stay where they were)."""
        tree = self.tree
        known = {
            name: value
            for name, value in positions.items()
            if name in tree.actuated_joints and math.isfinite(value)
        }
        tree.set_positions(known)
        world = tree.world_transforms()
        transforms = []
        for name in self._moving():
            joint = tree.joint(name)
            relative = np.linalg.solve(world[joint.parent], world[joint.child])
            transforms.append(_transform(joint.parent, joint.child, relative, stamp))
        return {"transforms": transforms}

    def description_message(self) -> dict[str, Any]:
        """/robot_description: the URDF as it is on disk."""
        return {"data": self.urdf_text}


def serve_meshes(text: str, base_dir: Path) -> tuple[str, dict[str, Path]]:
    """The URDF with its mesh references renamed for clients, and the files they name."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError:
        return text, {}
    found: dict[str, Path] = {}
    for mesh in root.iter("mesh"):
        filename = mesh.get("filename", "")
        if not filename or filename in found:
            continue
        try:
            found[filename] = find_mesh_file(filename, "live", base_dir, (), log.debug)
        except MeshSkippedError as err:
            log.warning("live: %s", err)
    renamed: dict[str, str] = {}
    for index, (filename, file) in enumerate(found.items()):
        relative = filename.removeprefix("package://")
        if filename.startswith(("/", "file://", "model://")) or ".." in Path(relative).parts:
            relative = f"{index}/{file.name}"
        renamed[filename] = ASSET_PACKAGE + relative
    served = _MESH_FILENAME.sub(
        lambda m: m.group(1) + m.group(2) + renamed.get(m.group(3), m.group(3)) + m.group(2),
        text,
    )
    return served, {renamed[name]: file for name, file in found.items()}


def diagnostics_message(report: DiagnosticReport, stamp: dict[str, int]) -> dict[str, Any]:
    """/diagnostics: the link's report, as ocu-ros publishes it."""
    return {
        "header": {"stamp": stamp, "frame_id": ""},
        "status": [
            {
                "level": int(report.level),
                "name": report.name,
                "message": report.message,
                "hardware_id": report.hardware_id,
                "values": [{"key": key, "value": value} for key, value in report.values],
            }
        ],
    }


def scan_message(scan: ScanFrame, stamp: dict[str, int]) -> dict[str, Any]:
    """/scan: sensor_msgs/msg/LaserScan in the range sensor's frame."""
    count = len(scan.ranges_m)
    return {
        "header": {"stamp": stamp, "frame_id": SCAN_FRAME},
        "angle_min": scan.angle_min_rad,
        "angle_max": scan.angle_min_rad + scan.angle_increment_rad * max(count - 1, 0),
        "angle_increment": scan.angle_increment_rad,
        "time_increment": 0.0,
        "scan_time": 0.0,
        "range_min": scan.range_min_m,
        "range_max": scan.range_max_m,
        "ranges": list(scan.ranges_m),
        "intensities": [],
    }
