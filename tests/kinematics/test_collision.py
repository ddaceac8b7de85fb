"""Self-collision from the URDF's collision geometry, and synchronized trajectories."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ocu.kinematics.arm import ArmKinematics, ToolPose
from ocu.kinematics.collision import (
    GROUND,
    path_violation,
    segment_box_distances,
    segment_distances,
)
from ocu.kinematics.trajectory import TrajectoryError, plan
from ocu.model.urdf import load_urdf
from ocu.profile import RobotProfile


@pytest.fixture(scope="module")
def arm(profile: RobotProfile) -> ArmKinematics:
    assert profile.arm is not None
    return ArmKinematics(load_urdf(meshes=False), profile.arm)


def test_segment_distance_hand_cases() -> None:
    p1 = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    q1 = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    p2 = np.array([[0.5, 1.0, -1.0], [2.0, 0.0, 1.0], [0.0, 2.0, 0.0], [3.0, 4.0, 0.0]])
    q2 = np.array([[0.5, 1.0, 1.0], [3.0, 0.0, 1.0], [1.0, 2.0, 0.0], [3.0, 4.0, 0.0]])
    # Crossing at a right angle 1 apart; end to end; parallel; point to point.
    assert np.allclose(segment_distances(p1, q1, p2, q2), [1.0, math.sqrt(2.0), 2.0, 5.0])


def test_segment_box_distance_matches_dense_sampling() -> None:
    rng = np.random.default_rng(2)
    starts = rng.uniform(-1.0, 1.0, (300, 3))
    ends = rng.uniform(-1.0, 1.0, (300, 3))
    halves = rng.uniform(0.05, 0.4, (300, 3))
    exact = segment_box_distances(starts, ends, halves)
    t = np.linspace(0.0, 1.0, 4001)
    points = starts[:, None, :] + t[None, :, None] * (ends - starts)[:, None, :]
    gap = np.maximum(np.abs(points) - halves[:, None, :], 0.0)
    sampled = np.sqrt(np.min(np.sum(gap * gap, axis=2), axis=1))
    assert np.all(exact <= sampled + 1e-12)
    assert np.allclose(exact, sampled, atol=1e-3)
    assert np.any(exact == 0.0)  # some pass through their box


def test_pairs_skip_neighbours_and_parts_that_never_move_apart(arm: ArmKinematics) -> None:
    pairs = set(arm.collision.pairs)
    assert ("forearm", "base_link") in pairs
    assert ("left_jaw", "left_flipper") in pairs
    assert ("upper_arm", "forearm") not in pairs  # neighbours: the elbow joins them
    assert ("left_jaw", "right_jaw") not in pairs  # only the gripper moves them apart
    assert ("turret", "base_link") not in pairs  # the waist turns the turret on the deck
    assert all(a in arm.collision.arm_links for a, _ in pairs)


def test_folding_the_arm_into_the_chassis_is_seen(arm: ArmKinematics) -> None:
    ready = arm.vector(arm.settings.poses["ready"])
    contact = arm.contact(ready, {})
    assert contact is not None
    assert contact.distance_m > arm.settings.clearance_m
    # Shoulder level, elbow folded right down: the head and gripper end up in the hull.
    folded = np.radians([0.0, 0.0, 150.0, 0.0])
    contact = arm.contact(folded, {})
    assert contact is not None
    assert contact.distance_m < 0.0
    assert "base_link" in (contact.link_a, contact.link_b)
    assert "overlap" in contact.describe()
    # Reaching down in front: the ground, not the chassis.
    down = np.radians([0.0, -10.0, 60.0, 0.0])
    contact = arm.contact(down, {})
    assert contact is not None
    assert contact.link_b == GROUND
    assert contact.distance_m < 0.0


def test_flippers_count_in_the_check(arm: ArmKinematics) -> None:
    """A flipper raised beside the gripper is an obstacle where a lowered one is not."""
    over_flipper = arm.solve(ToolPose(0.40, 0.33, 0.40, math.radians(-70.0)))
    lowered = arm.contact(over_flipper, {"flippers": 0.0})
    raised = arm.contact(over_flipper, {"flippers": math.radians(80.0)})
    assert lowered is not None
    assert raised is not None
    assert lowered.distance_m > arm.settings.clearance_m
    assert raised.distance_m < 0.0
    assert raised.link_b == "left_flipper"


def test_stored_poses_and_the_moves_between_them_are_clear(arm: ArmKinematics) -> None:
    poses = {name: arm.vector(angles) for name, angles in arm.settings.poses.items()}
    assert set(poses) == {"stow", "ready", "look_forward", "look_back"}
    speed, accel = np.full(4, 0.4), np.full(4, 1.5)
    for first in poses.values():
        for second in poses.values():
            move = plan(first, second, speed, accel)
            assert arm.check_path(move.points(40), {}) is None


def test_a_pair_too_close_at_the_start_may_only_move_apart_until_clear() -> None:
    clearance = 0.01
    # Columns: a pair clear throughout; one overlapping at the start that comes apart.
    leaving = np.array([[0.05, -0.001], [0.04, 0.0], [0.03, 0.02], [0.02, 0.03]])
    assert path_violation(leaving, clearance) is None
    # The same, but the clear pair comes within the clearance on the way.
    assert path_violation(np.array([[0.05, -0.001], [0.009, 0.0]]), clearance) == (1, 0)
    # Deeper first: refused where it gets worse than at the start.
    assert path_violation(np.array([[0.05, -0.001], [0.05, -0.002]]), clearance) == (1, 1)
    # Apart but not yet clear, then back toward it (no worse than the start): allowed;
    # once clear it must keep the clearance.
    assert (
        path_violation(np.array([[0.05, -0.001], [0.05, 0.005], [0.05, -0.001]]), clearance) is None
    )
    assert path_violation(np.array([[0.05, -0.001], [0.05, 0.02], [0.05, 0.005]]), clearance) == (
        2,
        1,
    )
    # Two poses wrong: the first is told, with its closest offending pair.
    bad = np.array([[0.05, 0.05], [0.005, 0.001], [-0.01, 0.05]])
    assert path_violation(bad, clearance) == (1, 1)


def test_a_path_out_of_an_overlap_is_allowed_and_deeper_is_refused(arm: ArmKinematics) -> None:
    """Folded with the head 1 mm into the turret (where a stall left it): the way out is not
    refused at 0 % any more; a way deeper in still is, naming the pair as it was."""
    too_close = arm.vector({"waist": 0.0, "shoulder": 0.0, "elbow": math.radians(-125.0),
                            "neck": math.radians(-79.2)})  # fmt: skip
    start = arm.contact(too_close, {})
    assert start is not None
    assert (start.link_a, start.link_b) == ("turret", "head_cameras")
    assert -0.0015 < start.distance_m < 0.0
    ready = arm.vector(arm.settings.poses["ready"])
    out = [too_close + (ready - too_close) * s for s in np.linspace(0.0, 1.0, 60)]
    assert arm.check_path(out, {}) is None
    deeper = too_close.copy()
    deeper[3] = math.radians(-70.0)
    hit = arm.check_path([too_close + (deeper - too_close) * s for s in np.linspace(0, 1, 20)], {})
    assert hit is not None
    assert hit.index == 1
    assert hit.describe(20) == (
        "the path comes too close at 5% of the way: turret and head_cameras overlap by 2 mm "
        "(at the start turret and head_cameras overlap by 1 mm: a move may only part them)"
    )


def test_synchronized_trapezoid_all_joints_start_and_arrive_together() -> None:
    start = np.array([0.0, 0.5, -1.0, 0.2])
    goal = np.array([1.0, 0.4, 0.5, 0.2])
    speed = np.array([0.5, 0.4, 0.4, 0.5])
    accel = np.array([1.0, 1.0, 1.0, 1.0])
    move = plan(start, goal, speed, accel)
    # The waist (1 rad at 0.5 rad/s) or the elbow (1.5 rad at 0.4 rad/s) decides: 1.5/0.4 +
    # the ramp 0.4/1.0 s.
    assert move.duration_s == pytest.approx(1.5 / 0.4 + 0.4, rel=1e-9)
    times = np.linspace(0.0, move.duration_s, 2001)
    samples = [move.sample(t) for t in times]
    positions = np.array([s[0] for s in samples])
    speeds = np.array([s[1] for s in samples])
    assert np.allclose(positions[0], start)
    assert np.allclose(positions[-1], goal)
    assert np.all(np.abs(speeds) <= speed + 1e-9)
    accelerations = np.diff(speeds, axis=0) / np.diff(times)[:, None]
    assert np.all(np.abs(accelerations) <= accel + 1e-6)
    # Proportional: every joint has covered the same share of its way at every instant.
    moving = np.abs(goal - start) > 0
    shares = (positions[:, moving] - start[moving]) / (goal - start)[moving]
    assert np.allclose(shares, shares[:, :1])
    # The speeds integrate to the path.
    integrated = start + np.trapezoid(speeds, times, axis=0)
    assert np.allclose(integrated, goal, atol=1e-4)


def test_short_moves_are_triangles_and_cubic_is_smooth() -> None:
    move = plan([0.0], [0.1], [1.0], [1.0])
    assert move.duration_s == pytest.approx(2.0 * math.sqrt(0.1))
    assert move.sample(move.duration_s / 2)[1][0] == pytest.approx(math.sqrt(0.1))
    cubic = plan([0.0, 0.0], [1.0, -2.0], [1.0, 1.0], [10.0, 10.0], profile="cubic")
    assert cubic.duration_s == pytest.approx(3.0)  # the joint moving 2 rad at 1 rad/s peak
    assert cubic.sample(0.0)[1] == pytest.approx([0.0, 0.0])
    assert cubic.sample(1.5)[1] == pytest.approx([0.5, -1.0])
    assert np.allclose(cubic.sample(3.0)[0], [1.0, -2.0])
    with pytest.raises(TrajectoryError, match="above zero"):
        plan([0.0], [1.0], [0.0], [1.0])
    assert plan([0.3], [0.3], [1.0], [1.0]).duration_s == 0.0
