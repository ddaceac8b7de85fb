"""The simulated robot's physics, stepped by hand: no sockets, no threads, no clock."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from ocu.profile import RobotProfile, load_profile
from ocu.records import Command
from ocu.sim.physics import (
    JOINT_CURRENT_A_PER_RAD_S,
    JOINT_IDLE_CURRENT_A,
    TRACK_CURRENT_A_PER_M_S,
    TRACK_IDLE_CURRENT_A,
    RobotPhysics,
)

T0_S = 100.0  # any monotonic time: nothing depends on where the clock starts


@pytest.fixture(scope="module")
def profile() -> RobotProfile:
    """The shipped Engineer profile."""
    return load_profile()


def test_initial_joints_zero_or_nearest_limit(profile: RobotProfile) -> None:
    neck = profile.motors["neck"]
    shifted = replace(neck, limits_rad=(0.1, 0.5))
    custom = replace(profile, motors={**profile.motors, "neck": shifted})
    physics = RobotPhysics(custom, {"elbow": 0.25}, now_s=T0_S)
    joints = physics.joints_rad
    assert joints["neck"] == 0.1
    assert joints["elbow"] == 0.25
    assert joints["waist"] == 0.0
    assert not any(profile.motors[name].track for name in joints)
    assert physics.time_s == T0_S
    assert physics.all_stopped
    assert physics.pose == (0.0, 0.0, 0.0)


def test_nothing_moves_without_a_command_and_time_never_runs_back(profile: RobotProfile) -> None:
    physics = RobotPhysics(profile, {"shoulder": 0.5}, now_s=T0_S)
    physics.advance(T0_S + 10.0)
    assert physics.joints_rad["shoulder"] == 0.5
    assert not physics.watchdog_stopped
    physics.advance(T0_S + 5.0)
    assert physics.time_s == T0_S + 10.0


def test_joint_integrates_at_the_commanded_speed(profile: RobotProfile) -> None:
    physics = RobotPhysics(profile, now_s=T0_S)
    physics.apply(Command({"shoulder": 0.4}), T0_S)
    assert physics.velocities["shoulder"] == 0.4
    for step in range(1, 51):
        physics.advance(T0_S + step * 0.01)
    assert physics.joints_rad["shoulder"] == pytest.approx(0.4 * 0.5, rel=1e-9)
    # A new command takes effect exactly from its own time.
    physics.apply(Command({"shoulder": -0.2}), T0_S + 0.75)
    assert physics.joints_rad["shoulder"] == pytest.approx(0.4 * 0.75, rel=1e-9)
    physics.advance(T0_S + 1.0)
    assert physics.joints_rad["shoulder"] == pytest.approx(0.4 * 0.75 - 0.2 * 0.25, rel=1e-9)


def test_joints_stop_at_their_limits(profile: RobotProfile) -> None:
    neck_limits = profile.motors["neck"].limits_rad
    gripper_limits = profile.motors["gripper"].limits_rad
    assert neck_limits is not None
    assert gripper_limits is not None
    physics = RobotPhysics(
        profile, {"neck": neck_limits[1] - 0.05, "gripper": gripper_limits[0]}, now_s=T0_S
    )
    physics.apply(Command({"neck": 0.5, "gripper": -0.5}), T0_S)
    assert physics.velocities["gripper"] == 0.0
    physics.advance(T0_S + 0.5)
    assert physics.joints_rad["neck"] == neck_limits[1]
    assert physics.velocities["neck"] == 0.0
    assert physics.commanded_velocities["neck"] == 0.5
    assert physics.joints_rad["gripper"] == gripper_limits[0]
    assert not physics.watchdog_stopped

    neck = physics.reading(profile.motors["neck"])
    assert neck.at_upper_limit
    assert not neck.at_lower_limit
    assert neck.speed == 0.0
    assert neck.speed_command == 0.5
    assert physics.reading(profile.motors["gripper"]).at_lower_limit
    waist = physics.reading(profile.motors["waist"])
    assert not waist.at_lower_limit
    assert not waist.at_upper_limit
    assert not waist.suppressed

    physics.apply(Command({"neck": -0.5}), T0_S + 0.6)
    physics.advance(T0_S + 0.7)
    assert physics.velocities["neck"] == -0.5
    assert physics.joints_rad["neck"] == pytest.approx(neck_limits[1] - 0.05)


def test_speed_below_min_speed_moves_nothing(profile: RobotProfile) -> None:
    waist_min = profile.channels["waist"].min_speed
    drive_min = profile.channels["drive_linear"].min_speed
    physics = RobotPhysics(profile, now_s=T0_S)
    physics.apply(Command({"waist": waist_min * 0.5, "drive_linear": drive_min * 0.75}), T0_S)
    physics.advance(T0_S + 0.3)
    assert physics.commanded_velocities["waist"] > 0.0
    assert physics.all_stopped
    assert physics.joints_rad["waist"] == 0.0
    assert physics.track_speeds_m_s == (0.0, 0.0)
    assert physics.pose == (0.0, 0.0, 0.0)

    physics.apply(Command({"waist": waist_min}), T0_S + 0.3)
    physics.advance(T0_S + 0.4)
    assert physics.velocities["waist"] == pytest.approx(waist_min)
    assert physics.joints_rad["waist"] == pytest.approx(waist_min * 0.1)


def test_the_drive_pair_starts_together(profile: RobotProfile) -> None:
    drive = profile.drive_channels
    assert drive is not None
    linear, turn = drive
    slow_m_s = profile.channels[linear].min_speed / 2.0
    physics = RobotPhysics(profile, now_s=T0_S)
    # A turn fast enough to start the tracks carries a linear speed below min_speed along.
    physics.apply(Command({linear: slow_m_s, turn: profile.channels[turn].min_speed}), T0_S)
    assert physics.velocities[linear] == slow_m_s
    left_m_s, right_m_s = physics.track_speeds_m_s
    assert (left_m_s + right_m_s) / 2.0 == pytest.approx(slow_m_s)
    # Both below min_speed: the tracks do not start.
    physics.apply(Command({linear: slow_m_s, turn: profile.channels[turn].min_speed / 2}), T0_S)
    assert physics.all_stopped


@pytest.mark.parametrize("drive", [{"drive_linear": 0.3}, {"drive_turn": 0.5}])
def test_waist_is_locked_while_the_chassis_moves(
    profile: RobotProfile, drive: dict[str, float]
) -> None:
    assert profile.channels["waist"].locked_while_driving
    physics = RobotPhysics(profile, now_s=T0_S)
    physics.apply(Command({**drive, "waist": 0.5}), T0_S)
    physics.advance(T0_S + 0.2)
    assert physics.waist_suppressed
    assert physics.velocities["waist"] == 0.0
    assert physics.joints_rad["waist"] == 0.0
    assert physics.track_speeds_m_s != (0.0, 0.0)
    waist = physics.reading(profile.motors["waist"])
    assert waist.suppressed
    assert waist.speed == 0.0
    assert waist.speed_command == 0.5
    assert not physics.reading(profile.motors["shoulder"]).suppressed

    physics.apply(Command({"waist": 0.5}), T0_S + 0.2)
    physics.advance(T0_S + 0.4)
    assert not physics.waist_suppressed
    assert physics.velocities["waist"] == 0.5
    assert physics.joints_rad["waist"] == pytest.approx(0.1)
    assert physics.track_speeds_m_s == (0.0, 0.0)


def test_watchdog_stops_at_its_expiry_even_when_the_step_comes_late(
    profile: RobotProfile,
) -> None:
    watchdog_s = profile.link.robot_watchdog_s
    physics = RobotPhysics(profile, now_s=T0_S)
    physics.apply(Command({"shoulder": 0.3, "drive_linear": 0.3}), T0_S)
    physics.advance(T0_S + watchdog_s)
    assert not physics.watchdog_stopped
    physics.advance(T0_S + watchdog_s + 2.0)
    assert physics.watchdog_stopped
    assert physics.all_stopped
    assert physics.track_speeds_m_s == (0.0, 0.0)
    assert all(speed == 0.0 for speed in physics.commanded_velocities.values())
    assert physics.joints_rad["shoulder"] == pytest.approx(0.3 * watchdog_s)
    assert physics.pose[0] == pytest.approx(0.3 * watchdog_s)
    for motor in profile.motors.values():
        reading = physics.reading(motor)
        assert reading.watchdog_stopped
        assert reading.speed_command == 0.0

    physics.apply(Command({"shoulder": 0.3}), T0_S + 5.0)
    assert not physics.watchdog_stopped
    assert physics.velocities["shoulder"] == 0.3


def test_pose_integrates_a_straight_drive_a_turn_and_an_arc(profile: RobotProfile) -> None:
    physics = RobotPhysics(profile, now_s=T0_S)
    physics.apply(Command({"drive_linear": 0.3}), T0_S)
    assert physics.track_speeds_m_s == (0.3, 0.3)
    physics.advance(T0_S + 0.4)
    assert physics.pose == pytest.approx((0.12, 0.0, 0.0))

    physics.apply(Command({"drive_turn": 0.5}), T0_S + 0.4)
    half_width_m = profile.track_width_m / 2.0
    assert physics.track_speeds_m_s == pytest.approx((-0.5 * half_width_m, 0.5 * half_width_m))
    physics.advance(T0_S + 0.8)
    assert physics.pose == pytest.approx((0.12, 0.0, 0.2))

    # A full circle in steps of about 10 ms (a command each, for the watchdog) comes back to
    # where it began, heading included.
    arc = Command({"drive_linear": 0.3, "drive_turn": 0.5})
    circle_s, steps = math.tau / 0.5, 1250
    for step in range(steps):
        physics.apply(arc, T0_S + 0.8 + step * circle_s / steps)
    physics.advance(T0_S + 0.8 + circle_s)
    x_m, y_m, heading_rad = physics.pose
    assert (x_m, y_m) == pytest.approx((0.12, 0.0), abs=1e-6)
    assert math.remainder(heading_rad - 0.2, math.tau) == pytest.approx(0.0, abs=1e-9)


def test_readings_model_the_currents_and_tracks(profile: RobotProfile) -> None:
    physics = RobotPhysics(profile, {"elbow": -1.0}, now_s=T0_S)
    physics.apply(Command({"elbow": 0.5, "drive_linear": 0.3}), T0_S)
    elbow = physics.reading(profile.motors["elbow"])
    assert elbow.angle_rad == -1.0
    assert elbow.speed == 0.5
    assert elbow.current_a == pytest.approx(JOINT_IDLE_CURRENT_A + JOINT_CURRENT_A_PER_RAD_S * 0.5)
    assert elbow.current_command_a == elbow.current_a
    idle = physics.reading(profile.motors["neck"])
    assert idle.current_a == JOINT_IDLE_CURRENT_A
    track = physics.reading(profile.motors["left_track"])
    assert track.angle_rad is None
    assert track.speed == 0.3
    assert track.current_a == pytest.approx(TRACK_IDLE_CURRENT_A + TRACK_CURRENT_A_PER_M_S * 0.3)
    assert not track.at_lower_limit
    assert not track.at_upper_limit
