"""A whole pose of tool0 as an operator types it: x, y, z and roll, pitch, yaw (numpy only).

Roll, pitch and yaw are ROS's convention (REP 103, the URDF's `rpy`, tf's `getRPY`): turns
about the fixed x, y and z axes of the base frame, in that order, so the rotation is
Rz(yaw) · Ry(pitch) · Rx(roll). The Arm dock of an arm with six joints or more (a UR) takes
a pose goal so, and `describe_pose` says one back the same way.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ocu.kinematics.chain import Vector
from ocu.model.tree import Matrix

# Below this the pitch is taken as ±90° (gimbal lock): roll and yaw turn about the same
# axis, and the yaw takes the whole turn.
GIMBAL_EPS = 1e-9


def pose_from_rpy(position: Sequence[float] | Vector, rpy: Sequence[float]) -> Matrix:
    """The 4x4 pose: position (x, y, z m) and roll, pitch, yaw (rad) about the fixed x, y, z
    axes."""
    roll, pitch, yaw = (float(v) for v in rpy)
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    pose = np.eye(4)
    pose[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    pose[:3, 3] = [float(v) for v in position]
    return pose


def rpy_of(pose: Matrix) -> tuple[float, float, float]:
    """Roll, pitch, yaw (rad) of a rotation (3x3 or 4x4); pitch in [-90°, 90°]."""
    r = np.asarray(pose, dtype=float)[:3, :3]
    cp = math.hypot(r[0, 0], r[1, 0])
    pitch = math.atan2(-r[2, 0], cp)
    if cp < GIMBAL_EPS:
        return 0.0, pitch, math.atan2(-r[0, 1], r[1, 1])
    return math.atan2(r[2, 1], r[2, 2]), pitch, math.atan2(r[1, 0], r[0, 0])


def angle_between(a: Matrix, b: Matrix) -> float:
    """The angle (rad) of the rotation that takes one orientation to the other."""
    r = np.asarray(a, dtype=float)[:3, :3].T @ np.asarray(b, dtype=float)[:3, :3]
    # atan2 of the sine (the skew part) and the cosine: exact near 0 where acos is not.
    sine = float(np.linalg.norm([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])) / 2
    return math.atan2(sine, (float(np.trace(r)) - 1.0) / 2.0)


def describe_pose(pose: Matrix) -> str:
    """'x 512 y -3 z 280 mm, roll 180.0° pitch 0.0° yaw -90.0°'."""

    def number(value: float, decimals: int) -> str:
        text = f"{value:.{decimals}f}"
        return text[1:] if text.startswith("-") and float(text) == 0.0 else text

    x, y, z = (float(v) * 1000 for v in np.asarray(pose)[:3, 3])
    roll, pitch, yaw = (math.degrees(v) for v in rpy_of(pose))
    return (
        f"x {number(x, 0)} y {number(y, 0)} z {number(z, 0)} mm, roll {number(roll, 1)}° "
        f"pitch {number(pitch, 1)}° yaw {number(yaw, 1)}°"
    )
