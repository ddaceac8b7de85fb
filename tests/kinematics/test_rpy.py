"""Roll, pitch, yaw as ROS has them (ocu.kinematics.rpy), checked against tf2's own formula."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from ocu.kinematics.rpy import angle_between, describe_pose, pose_from_rpy, rpy_of
from ocu.ros.convert import rotation_of

ANGLE = st.floats(-math.pi, math.pi, allow_nan=False)


def tf2_quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """tf2::Quaternion::setRPY (x, y, z, w), written out as tf2 has it."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


@given(ANGLE, ANGLE, ANGLE)
def test_the_rotation_is_tf2s_and_its_angles_come_back(
    roll: float, pitch: float, yaw: float
) -> None:
    pose = pose_from_rpy((0.1, -0.2, 0.3), (roll, pitch, yaw))
    assert np.allclose(pose[:3, :3], rotation_of(*tf2_quaternion(roll, pitch, yaw)), atol=1e-9)
    assert np.allclose(pose[:3, 3], (0.1, -0.2, 0.3))
    back = pose_from_rpy((0, 0, 0), rpy_of(pose))
    assert angle_between(pose, back) < 1e-6  # the same orientation (angles may differ)
    assert -math.pi / 2 <= rpy_of(pose)[1] <= math.pi / 2


def test_gimbal_lock_and_a_plain_description() -> None:
    pose = pose_from_rpy((0.5, 0, 0.25), (0.4, math.pi / 2, 0.1))
    roll, pitch, yaw = rpy_of(pose)
    assert math.isclose(pitch, math.pi / 2)
    assert roll == 0.0
    assert angle_between(pose, pose_from_rpy((0, 0, 0), (roll, pitch, yaw))) < 1e-9
    tool_down = pose_from_rpy((0.512, -0.003, 0.28), (math.pi, 0, -math.pi / 2))
    assert describe_pose(tool_down) == "x 512 y -3 z 280 mm, roll 180.0° pitch 0.0° yaw -90.0°"
    assert math.isclose(angle_between(np.eye(3), pose_from_rpy((0, 0, 0), (0, 0, 0.3))), 0.3)
