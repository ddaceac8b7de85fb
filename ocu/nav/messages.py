"""The navigator's state as the contents of ROS messages, without ROS: nav_msgs/Odometry and
the tf odom -> base_link (the ROS node's bridge and the live server publish the same)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ocu.nav.odometry import OdometryEstimate

ODOM_FRAME = "odom"
BASE_FRAME = "base_link"
# The covariance ROS wants is 6x6 over (x, y, z, roll, pitch, yaw); a crawler on the floor
# knows z, roll and pitch only loosely: this large variance says "not estimated".
UNKNOWN_VARIANCE = 1e6


@dataclass(frozen=True)
class OdometryData:
    """nav_msgs/Odometry's contents (and the tf odom -> base_link)."""

    frame_id: str
    child_frame_id: str
    position: tuple[float, float, float]
    orientation_xyzw: tuple[float, float, float, float]
    pose_covariance: tuple[float, ...]
    linear: tuple[float, float, float]
    angular: tuple[float, float, float]
    twist_covariance: tuple[float, ...]


def yaw_quaternion(yaw_rad: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation about z."""
    return (0.0, 0.0, math.sin(yaw_rad / 2.0), math.cos(yaw_rad / 2.0))


def quaternion_yaw(x: float, y: float, z: float, w: float) -> float:
    """The rotation about z of a quaternion."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def odometry_data(estimate: OdometryEstimate) -> OdometryData:
    """The estimate as nav_msgs/Odometry: pose with its covariance, the speeds in base_link."""
    pose = estimate.pose
    cov = estimate.covariance
    pose_cov = [0.0] * 36
    index = {0: 0, 1: 1, 2: 5}  # x, y, yaw in the 6x6 matrix
    for row, r in index.items():
        for column, c in index.items():
            pose_cov[r * 6 + c] = float(cov[row, column])
    for axis in (2, 3, 4):
        pose_cov[axis * 6 + axis] = UNKNOWN_VARIANCE
    twist_cov = [0.0] * 36
    for axis in (1, 2, 3, 4):
        twist_cov[axis * 6 + axis] = UNKNOWN_VARIANCE
    return OdometryData(
        frame_id=ODOM_FRAME,
        child_frame_id=BASE_FRAME,
        position=(pose.x_m, pose.y_m, 0.0),
        orientation_xyzw=yaw_quaternion(pose.heading_rad),
        pose_covariance=tuple(pose_cov),
        linear=(estimate.linear_m_s, 0.0, 0.0),
        angular=(0.0, 0.0, estimate.angular_rad_s),
        twist_covariance=tuple(twist_cov),
    )
