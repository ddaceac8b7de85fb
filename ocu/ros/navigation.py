"""The ROS side of driving with a map, without ROS or Qt: messages as plain data and the
frames of other nodes' scans (the zones and the path mode are the console model's).

- `odometry_data` (ocu.nav.messages, shared with the live server): nav_msgs/Odometry (frame
  `odom`, child `base_link`) and the matching tf.
- `laser_scan_data` / `scan_from_ros`: sensor_msgs/LaserScan both ways.
- `FrameTree`: the transforms other nodes publish on /tf and /tf_static, enough to place a
  planar scan taken in a frame below `base_link` (a laser's frame); unknown frames are refused.
- `path_points`: a nav_msgs/Path in `odom` as waypoints (other frames are refused), each
  position within `MAX_PATH_COORDINATE_M` of the origin.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ocu.nav.messages import (
    BASE_FRAME,
    ODOM_FRAME,
    UNKNOWN_VARIANCE,
    OdometryData,
    odometry_data,
    quaternion_yaw,
    yaw_quaternion,
)
from ocu.records import SCAN_FROM_ROS, ScanFrame
from ocu.ros.convert import BridgeError, quoted, rotation_of

# A path the path mode drives at 0.25 m/s: a pose farther than this (10 km) is a broken
# message, and its arithmetic would overflow (1e308 squared).
MAX_PATH_COORDINATE_M = 1e4
# A scan's frame counts as level (its plane the floor's) within this tilt.
MAX_SCAN_TILT_RAD = math.radians(5.0)
# Deeper than this, a chain of frames is a loop or a broken tree.
MAX_FRAME_DEPTH = 32
# More beams than a planar laser has (0.1° over a full turn is 3600): the zones' search
# holds every point at every step of the arc, and a million-beam scan would take gigabytes.
MAX_SCAN_BEAMS = 4096


__all__ = [
    "BASE_FRAME",
    "ODOM_FRAME",
    "UNKNOWN_VARIANCE",
    "FrameTree",
    "LaserScanData",
    "NavigationError",
    "OdometryData",
    "PlanarMount",
    "laser_scan_data",
    "odometry_data",
    "path_points",
    "quaternion_yaw",
    "scan_from_ros",
    "yaw_quaternion",
]


class NavigationError(ValueError):
    """A message the node cannot use (a path in another frame, a malformed scan)."""


@dataclass(frozen=True)
class LaserScanData:
    """sensor_msgs/LaserScan's contents (ranges: inf beyond range_max, nan unmeasured)."""

    frame_id: str
    angle_min: float
    angle_max: float
    angle_increment: float
    scan_time: float
    range_min: float
    range_max: float
    ranges: tuple[float, ...]


def laser_scan_data(scan: ScanFrame, scan_period_s: float = 0.0) -> LaserScanData:
    """A robot's scan as sensor_msgs/LaserScan, in base_link (the sensor's mount is in the
    profile; a static transform for it is the launch file's business)."""
    count = len(scan.ranges_m)
    return LaserScanData(
        frame_id=BASE_FRAME,
        angle_min=scan.angle_min_rad,
        angle_max=scan.angle_min_rad + scan.angle_increment_rad * (count - 1),
        angle_increment=scan.angle_increment_rad,
        scan_time=scan_period_s,
        range_min=scan.range_min_m,
        range_max=scan.range_max_m,
        ranges=scan.ranges_m,
    )


def scan_from_ros(
    *,
    angle_min: float,
    angle_increment: float,
    range_min: float,
    range_max: float,
    ranges: Sequence[float],
    received_at: float,
    wall_time: float,
) -> ScanFrame:
    """Another node's LaserScan for the zones; NavigationError if it makes no sense."""
    values = (angle_min, angle_increment, range_min, range_max)
    if not all(math.isfinite(v) for v in values) or angle_increment == 0.0 or not ranges:
        raise NavigationError("LaserScan: angles and limits must be finite, beams present")
    if len(ranges) > MAX_SCAN_BEAMS:
        raise NavigationError(f"LaserScan: {len(ranges)} beams, at most {MAX_SCAN_BEAMS}")
    if not 0.0 <= range_min < range_max:
        raise NavigationError(f"LaserScan: range_min {range_min} not below range_max {range_max}")
    # REP 117: below range_min or nan is no measurement; above range_max, or +inf, no return.
    cleaned = tuple(
        math.nan if math.isnan(r) or r < range_min else math.inf if r > range_max else float(r)
        for r in ranges
    )
    return ScanFrame(
        angle_min_rad=angle_min,
        angle_increment_rad=angle_increment,
        range_min_m=range_min,
        range_max_m=range_max,
        ranges_m=cleaned,
        received_at=received_at,
        wall_time=wall_time,
        source=SCAN_FROM_ROS,
    )


def path_points(frame_id: str, points: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    """A nav_msgs/Path's positions as waypoints in odom; NavigationError otherwise."""
    frame = frame_id.lstrip("/")
    if frame not in (ODOM_FRAME, ""):
        raise NavigationError(f"follow_path: the path is in {quoted(frame_id)}; give it in 'odom'")
    checked = [(float(x), float(y)) for x, y in points]
    if not checked:
        raise NavigationError("follow_path: the path has no poses")
    for index, point in enumerate(checked):
        if not all(math.isfinite(v) and abs(v) <= MAX_PATH_COORDINATE_M for v in point):
            raise NavigationError(
                f"follow_path: pose {index} at ({point[0]:.4g}, {point[1]:.4g}) m is not "
                f"within {MAX_PATH_COORDINATE_M:g} m of the origin: path refused"
            )
    return checked


@dataclass(frozen=True)
class PlanarMount:
    """Where a level sensor sits on the chassis: its origin in base_link and its yaw."""

    x_m: float
    y_m: float
    yaw_rad: float

    def place(self, scan: ScanFrame) -> ScanFrame:
        """The scan with its beams turned by the yaw (its origin is `x_m, y_m`)."""
        if self.yaw_rad == 0.0:
            return scan
        angle = math.remainder(scan.angle_min_rad + self.yaw_rad, math.tau)
        return replace(scan, angle_min_rad=angle)


class FrameTree:
    """The latest transform of each child frame (from /tf and /tf_static), and the planar
    mount of a frame below `base_link` composed from them. Thread-safe, ROS-free.

    Each scan is placed by its `frame_id`: `base_link` itself, or a frame whose chain of
    parents reaches `base_link` (a laser's static transform from the launch file). Any other
    frame is unknown and its scans refused: a scan of somewhere else read as the robot's
    surroundings would hide or invent obstacles.
    """

    def __init__(self, base: str = BASE_FRAME) -> None:
        self.base = base
        self._lock = threading.Lock()
        self._parents: dict[str, tuple[str, np.ndarray]] = {}

    def set(
        self,
        parent: str,
        child: str,
        translation: Sequence[float],
        rotation_xyzw: Sequence[float],
    ) -> None:
        """One transform (child's pose in parent); NavigationError if it is not a pose."""
        parent, child = parent.lstrip("/"), child.lstrip("/")
        values = [float(v) for v in translation]
        if not parent or not child or len(values) != 3 or not all(map(math.isfinite, values)):
            raise NavigationError("a transform needs two frames and a finite translation")
        try:
            rotation = rotation_of(*(float(v) for v in rotation_xyzw))
        except BridgeError as err:
            raise NavigationError(str(err)) from err
        matrix = np.eye(4)
        matrix[:3, :3] = rotation
        matrix[:3, 3] = values
        with self._lock:
            self._parents[child] = (parent, matrix)

    def mount(self, frame_id: str) -> PlanarMount:
        """Where a scan in `frame_id` is taken; NavigationError for unknown or tilted frames."""
        frame = frame_id.lstrip("/")
        if not frame:
            raise NavigationError(f"no frame_id: say where the sensor is ({self.base!r} or below)")
        pose = np.eye(4)
        name = frame
        with self._lock:
            for _ in range(MAX_FRAME_DEPTH):
                if name == self.base:
                    break
                link = self._parents.get(name)
                if link is None:
                    raise NavigationError(
                        f"frame {quoted(frame)} is unknown: neither {self.base!r} nor linked to "
                        "it by /tf or /tf_static"
                    )
                name, matrix = link
                pose = matrix @ pose
            else:
                raise NavigationError(f"frame {quoted(frame)}: its chain of transforms loops")
        if pose[2, 2] < math.cos(MAX_SCAN_TILT_RAD):
            tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(pose[2, 2])))))
            raise NavigationError(
                f"frame {quoted(frame)} is tilted {tilt:.0f}° from {self.base!r}'s floor plane: "
                "a planar scan in it is not level"
            )
        yaw = math.atan2(float(pose[1, 0]), float(pose[0, 0]))
        return PlanarMount(float(pose[0, 3]), float(pose[1, 3]), yaw)
