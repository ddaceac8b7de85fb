"""Driving with a map, served live: the navigator's odometry, occupancy grid and planned path
and the chassis's footprint as ROS 2 messages (`/odom`, the tf odom -> base_link on `/tf`,
`/map`, `/plan`, `/footprint`).

The navigator is the console model's (ocu.nav.navigator); `estimate()` takes the
navigator's own lock for a few microseconds, as the ROS node's bridge does. The grid is read
without a lock: a map drawn while a scan is being added shows that scan in part, which the
next map completes.
"""

from __future__ import annotations

import struct
from typing import Any, Final, Protocol

import numpy as np

from ocu.nav.grid import OccupancyGrid
from ocu.nav.messages import BASE_FRAME, ODOM_FRAME, odometry_data
from ocu.nav.odometry import OdometryEstimate
from ocu.record import schemas as s

ODOM: Final = "/odom"
MAP: Final = "/map"
PLAN: Final = "/plan"
FOOTPRINT: Final = "/footprint"
ODOM_PERIOD_S: Final = 0.05
_COUNT: Final = struct.Struct("<I")  # a sequence's count in little-endian CDR
MAP_PERIOD_S: Final = 1.0

_TIME = "int32 sec\nuint32 nanosec\n"
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
_POINT = "float64 x\nfloat64 y\nfloat64 z\n"
_QUATERNION = "float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"
_POSE = ("geometry_msgs/Pose", "Point position\nQuaternion orientation\n")

ODOMETRY = s.MessageType(
    "nav_msgs/msg/Odometry",
    s.concatenate(
        "std_msgs/Header header\nstring child_frame_id\n"
        "geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
        ("geometry_msgs/PoseWithCovariance", "Pose pose\nfloat64[36] covariance\n"),
        _POSE,
        ("geometry_msgs/Point", _POINT),
        ("geometry_msgs/Quaternion", _QUATERNION),
        ("geometry_msgs/TwistWithCovariance", "Twist twist\nfloat64[36] covariance\n"),
        ("geometry_msgs/Twist", "Vector3 linear\nVector3 angular\n"),
        ("geometry_msgs/Vector3", _POINT),
    ),
)

OCCUPANCY_GRID = s.MessageType(
    "nav_msgs/msg/OccupancyGrid",
    s.concatenate(
        "std_msgs/Header header\nMapMetaData info\nint8[] data\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
        (
            "nav_msgs/MapMetaData",
            "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\n"
            "uint32 height\ngeometry_msgs/Pose origin\n",
        ),
        _POSE,
        ("geometry_msgs/Point", _POINT),
        ("geometry_msgs/Quaternion", _QUATERNION),
    ),
)


PATH = s.MessageType(
    "nav_msgs/msg/Path",
    s.concatenate(
        "std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
        ("geometry_msgs/PoseStamped", "std_msgs/Header header\nPose pose\n"),
        _POSE,
        ("geometry_msgs/Point", _POINT),
        ("geometry_msgs/Quaternion", _QUATERNION),
    ),
)

POLYGON_STAMPED = s.MessageType(
    "geometry_msgs/msg/PolygonStamped",
    s.concatenate(
        "std_msgs/Header header\nPolygon polygon\n",
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
        ("geometry_msgs/Polygon", "Point32[] points\n"),
        ("geometry_msgs/Point32", "float32 x\nfloat32 y\nfloat32 z\n"),
    ),
)


class NavigationSource(Protocol):
    """What the live server reads of a navigator."""

    grid: OccupancyGrid | None

    def estimate(self, now: float | None = None) -> OdometryEstimate: ...

    def planned_path(self) -> np.ndarray[Any, Any]: ...


def _xyz(values: tuple[float, float, float]) -> dict[str, float]:
    return {"x": values[0], "y": values[1], "z": values[2]}


def odometry_message(estimate: OdometryEstimate, stamp: dict[str, int]) -> dict[str, Any]:
    """/odom: the pose in `odom` with its covariance, the speeds in `base_link`."""
    data = odometry_data(estimate)
    x, y, z, w = data.orientation_xyzw
    return {
        "header": {"stamp": stamp, "frame_id": data.frame_id},
        "child_frame_id": data.child_frame_id,
        "pose": {
            "pose": {
                "position": _xyz(data.position),
                "orientation": {"x": x, "y": y, "z": z, "w": w},
            },
            "covariance": list(data.pose_covariance),
        },
        "twist": {
            "twist": {"linear": _xyz(data.linear), "angular": _xyz(data.angular)},
            "covariance": list(data.twist_covariance),
        },
    }


def odometry_transform(estimate: OdometryEstimate, stamp: dict[str, int]) -> dict[str, Any]:
    """/tf: odom -> base_link, where the robot is on the map."""
    data = odometry_data(estimate)
    x, y, z, w = data.orientation_xyzw
    return {
        "transforms": [
            {
                "header": {"stamp": stamp, "frame_id": ODOM_FRAME},
                "child_frame_id": BASE_FRAME,
                "transform": {
                    "translation": _xyz(data.position),
                    "rotation": {"x": x, "y": y, "z": z, "w": w},
                },
            }
        ]
    }


def encode_grid(encoder: s.Encoder, grid: OccupancyGrid, stamp: dict[str, int]) -> bytes:
    """/map as CDR: occupancy in percent, -1 where nothing was seen, row-major from the origin.

    The generic encoder takes an int8[] element by element (seconds for a 800 x 800 map);
    `data` is the message's last field, so the message is encoded with none and the cells
    are appended after their count (CDR: a uint32 count, then the bytes).
    """
    log_odds = np.array(grid.log_odds, dtype=np.float32)  # a copy: scans go on meanwhile
    percent = np.rint(100.0 / (1.0 + np.exp(-log_odds))).astype(np.int8)
    percent[log_odds == 0.0] = -1
    head = encoder(grid_message(grid, stamp))
    return head[:-4] + _COUNT.pack(percent.size) + percent.tobytes()


def grid_message(grid: OccupancyGrid, stamp: dict[str, int]) -> dict[str, Any]:
    """/map without its cells (see encode_grid)."""
    return {
        "header": {"stamp": stamp, "frame_id": ODOM_FRAME},
        "info": {
            "map_load_time": stamp,
            "resolution": grid.resolution_m,
            "width": grid.cells,
            "height": grid.cells,
            "origin": {
                "position": {"x": grid.origin_m[0], "y": grid.origin_m[1], "z": 0.0},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
            },
        },
        "data": [],
    }


def path_message(points: np.ndarray[Any, Any], stamp: dict[str, int]) -> dict[str, Any]:
    """/plan: the path (or the shuttle's two points) an assisted mode drives, in `odom`;
    no poses when none runs."""
    header = {"stamp": stamp, "frame_id": ODOM_FRAME}
    identity = {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    poses = [
        {
            "header": header,
            "pose": {"position": {"x": float(x), "y": float(y), "z": 0.0}, "orientation": identity},
        }
        for x, y in points
    ]
    return {"header": header, "poses": poses}


def footprint_message(
    corners_m: tuple[tuple[float, float], ...], stamp: dict[str, int]
) -> dict[str, Any]:
    """/footprint: the chassis outline about the turn centre, in `base_link`."""
    points = [{"x": x, "y": y, "z": 0.0} for x, y in corners_m]
    return {"header": {"stamp": stamp, "frame_id": BASE_FRAME}, "polygon": {"points": points}}
