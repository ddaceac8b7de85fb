"""The jog's task spaces (ocu.control.arm_task): the rotation vector there and back."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from ocu.control.arm_task import rotation_exp, rotation_log
from ocu.kinematics.rpy import angle_between, pose_from_rpy

COMPONENT = st.floats(-1.7, 1.7, allow_nan=False)  # under half a turn in all


@given(COMPONENT, COMPONENT, COMPONENT)
def test_a_rotation_vector_comes_back_from_its_rotation(x: float, y: float, z: float) -> None:
    omega = np.array([x, y, z])
    rotation = rotation_exp(omega)
    assert np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert math.isclose(float(np.linalg.det(rotation)), 1.0, abs_tol=1e-12)
    assert math.isclose(
        angle_between(np.eye(3), rotation), float(np.linalg.norm(omega)), abs_tol=1e-9
    )
    assert np.allclose(rotation_exp(rotation_log(rotation)), rotation, atol=1e-9)


def test_half_a_turn_and_none() -> None:
    for rpy in ((math.pi, 0, 0), (0, 0, math.pi), (math.pi, 0, math.pi / 2)):
        rotation = pose_from_rpy((0, 0, 0), rpy)[:3, :3]
        omega = rotation_log(rotation)
        assert math.isclose(float(np.linalg.norm(omega)), math.pi, abs_tol=1e-6)
        assert np.allclose(rotation_exp(omega), rotation, atol=1e-6)
    assert np.allclose(rotation_log(np.eye(3)), 0.0)
