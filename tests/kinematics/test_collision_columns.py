"""The collision model's columns: `gaps_along` measures exactly the pairs it keeps.

Pairs that touch in the reference pose are parts that fit together and are dropped when the
model is built; the batched measurement's index arrays must be built over the pairs kept.
They were built over every pair (during the reference measurement) and never again, so on an
arm with such a pair (the xArm 1S) `gaps_along` had more columns than `pair_contact` names:
a path check that hit the ground raised IndexError, and fitted parts were checked.
"""

from __future__ import annotations

import numpy as np

from ocu.kinematics.arm import ArmKinematics
from ocu.model.urdf import load_urdf
from ocu.profile.xarm import load_xarm_profile
from ocu.profile.xarm_robot import xarm_robot_profile


def xarm_kinematics() -> ArmKinematics:
    profile = xarm_robot_profile(load_xarm_profile("xarm1s"))
    assert profile.arm is not None
    return ArmKinematics(load_urdf(profile.urdf, meshes=False), profile.arm)


def test_every_column_of_the_xarms_gaps_is_a_pair_it_names() -> None:
    kinematics = xarm_kinematics()
    collision = kinematics.collision
    assert collision is not None
    gaps = collision.gaps_along([dict.fromkeys(kinematics.joints, 0.0)])
    grounded = gaps.shape[1] - collision.pair_count
    assert grounded >= 0
    for column in range(gaps.shape[1]):
        contact = collision.pair_contact(column, float(gaps[0, column]))
        assert contact.distance_m == float(gaps[0, column])
    # The pairs kept are clear in the reference pose (fitted parts are not checked).
    assert np.all(gaps[0, : collision.pair_count] > 0.0)


def test_a_path_into_the_table_is_refused_with_the_reason() -> None:
    kinematics = xarm_kinematics()
    start = np.radians([0.0, 30.0, 60.0, 40.0])
    down = np.radians([0.0, 95.0, 60.0, 40.0])  # the shoulder far forward: tool0 in the table
    points = [start + (down - start) * t for t in np.linspace(0.0, 1.0, 20)]
    hit = kinematics.check_path(points, {})
    assert hit is not None
    assert "ground" in hit.describe(len(points))
