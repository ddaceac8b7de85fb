"""Seed 003's geometric IK on the xArm's URDF (written from the profile's link lengths): the
closed-form solver takes the chain, agrees with the seed's own formulas (§2.3), gives both
elbow branches, and refuses the unreachable with the reason."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ocu.kinematics.analytic import ELBOW_DOWN, ELBOW_UP
from ocu.kinematics.arm import ArmError, ArmKinematics, ToolPose
from ocu.model.urdf import load_urdf
from ocu.profile.xarm import load_xarm_profile
from ocu.profile.xarm_robot import xarm_robot_profile


@pytest.fixture(scope="module")
def kinematics() -> ArmKinematics:
    profile = xarm_robot_profile(load_xarm_profile("xarm1s"))
    assert profile.arm is not None
    assert profile.urdf is not None
    return ArmKinematics(load_urdf(profile.urdf, meshes=False), profile.arm)


def seed_003(
    x: float, y: float, z: float, alpha: float, lengths: tuple[float, ...]
) -> tuple[float, float, float, float]:
    """θ6, θ5, θ4, θ3 by seed 003's equations (§2.3, configuration 1 and 2)."""
    l1, l2, l3, l4 = lengths
    pd, cd = l4 * math.sin(alpha), l4 * math.cos(alpha)
    af = math.hypot(x, y) - cd
    cf = z - l1 - pd
    ac = math.hypot(af, cf)
    abc = math.acos((l2**2 + l3**2 - ac**2) / (2 * l2 * l3))
    theta4 = math.pi - abc
    cab = math.acos((ac**2 + l2**2 - l3**2) / (2 * l2 * ac))
    caf = math.atan(abs(cf) / af)
    theta5 = cab + caf if cf >= 0 else cab - caf
    theta3 = alpha - theta5 + theta4
    return math.atan2(y, x), theta5, theta4, theta3


def test_the_xarm_chain_is_seed_003s_geometry(kinematics: ArmKinematics) -> None:
    analytic = kinematics.analytic
    assert analytic is not None  # the closed form, not the numeric fallback
    assert analytic.upper_m == pytest.approx(0.102)
    assert analytic.fore_m == pytest.approx(0.096)
    assert analytic.shoulder[1] == pytest.approx(0.061)
    assert math.hypot(*analytic.tool_offset) == pytest.approx(0.166)


@pytest.mark.parametrize(
    ("x", "y", "z", "pitch_deg"),
    [
        (0.20, 0.00, 0.10, -30.0),  # configuration 1: C above F
        (0.12, 0.10, 0.25, 20.0),
        (0.25, -0.05, -0.0, -60.0),  # configuration 2: C below F (CF < 0)
    ],
)
def test_elbow_up_is_seed_003s_solution(
    kinematics: ArmKinematics, x: float, y: float, z: float, pitch_deg: float
) -> None:
    alpha = math.radians(pitch_deg)
    lengths = load_xarm_profile("xarm1s").link_lengths_m
    theta6, theta5, theta4, theta3 = seed_003(x, y, z, alpha, lengths)
    q = kinematics.solve(ToolPose(x, y, z, alpha), elbow=ELBOW_UP)
    # The URDF stands up at zero and leans forward for a positive pitch joint.
    expected = [theta6, math.pi / 2 - theta5, theta4, -theta3]
    assert list(q) == pytest.approx(expected, abs=1e-9)
    pose = kinematics.tool_pose(q)
    assert (pose.x, pose.y, pose.z, pose.pitch) == pytest.approx((x, y, z, alpha), abs=1e-9)


def test_both_branches_reach_the_same_pose(kinematics: ArmKinematics) -> None:
    target = ToolPose(0.25, 0.05, 0.1, math.radians(-30.0))
    up = kinematics.solve(target, elbow=ELBOW_UP)
    down = kinematics.solve(target, elbow=ELBOW_DOWN)
    assert up[2] > 0 > down[2]  # the elbow bends one way, then the other
    for q in (up, down):
        pose = kinematics.tool_pose(q)
        assert (pose.x, pose.y, pose.z, pose.pitch) == pytest.approx(
            (target.x, target.y, target.z, target.pitch), abs=1e-9
        )


def test_round_trips_over_the_joint_ranges(kinematics: ArmKinematics) -> None:
    rng = np.random.default_rng(3)
    solved = 0
    for _ in range(200):
        q = rng.uniform(-1.2, 1.2, size=4)
        pose = kinematics.tool_pose(q)
        try:
            back = kinematics.solve(pose, current=q)
        except ArmError:
            continue  # the other branch may be out of the limits; this one must not be
        solved += 1
        again = kinematics.tool_pose(back)
        assert (again.x, again.y, again.z, again.pitch) == pytest.approx(
            (pose.x, pose.y, pose.z, pose.pitch), abs=1e-9
        )
    assert solved >= 190


@pytest.mark.parametrize(
    ("target", "reason"),
    [
        (ToolPose(0.5, 0.0, 0.1, 0.0), "out of reach"),
        (ToolPose(0.17, 0.0, 0.061, 0.0), "too close"),
    ],
)
def test_the_unreachable_is_refused_with_the_reason(
    kinematics: ArmKinematics, target: ToolPose, reason: str
) -> None:
    with pytest.raises(ArmError, match=reason):
        kinematics.solve(target)
