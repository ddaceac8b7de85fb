"""The arm controller without the console: streamed twists time out, missing or implausible
readings refuse motion, slow speeds pulse at the servo's starting speed."""

from __future__ import annotations

import math

import pytest

from ocu.control.arm import ArmController
from ocu.control.commands import VelocityLimits
from ocu.control.position import PositionController
from ocu.kinematics.arm import ArmError, ArmKinematics
from ocu.model.urdf import load_urdf
from ocu.profile import RobotProfile
from ocu.records import Command, JointReading
from tests.control.delayed_robot import DelayedRobot


def _rig(profile: RobotProfile) -> tuple[ArmController, PositionController, DelayedRobot]:
    assert profile.arm is not None
    limits = VelocityLimits(profile)
    position = PositionController(profile, limits)
    arm = ArmController(
        profile, limits, ArmKinematics(load_urdf(meshes=False), profile.arm), position
    )

    def deliver(readings: dict[str, JointReading], at: float, delay: float) -> None:
        position.on_telemetry(readings, at, delay)
        arm.observe(readings)

    robot = DelayedRobot(
        profile, profile.arm.poses["ready"], latency_s=0.05, telemetry_hz=10.0, deliver=deliver
    )
    return arm, position, robot


def test_a_streamed_twist_stops_soon_after_the_last_one(profile: RobotProfile) -> None:
    arm, _, robot = _rig(profile)
    with pytest.raises(ArmError, match="no reading of the waist yet"):
        arm.plan_move(profile.arm.poses["stow"], 0.0)  # type: ignore[union-attr]
    robot.run_until(0.5)
    timeout = profile.arm.twist_timeout_s  # type: ignore[union-attr]
    arm.jog([0.0, 0.05, 0.0, 0.0], "base", 0.5, expires_after_s=timeout)
    assert arm.update(0.5 + timeout / 2)
    assert arm.update(0.5 + timeout * 1.5) == {}
    assert not arm.active
    assert arm.pop_messages() == [f"arm: no twist for {timeout:g} s, jog stopped"]
    with pytest.raises(ArmError, match="four finite numbers"):
        arm.jog([0.0, math.nan, 0.0, 0.0], "base", 1.0)
    with pytest.raises(ArmError, match="unknown jog frame 'world'"):
        arm.jog([0.0, 0.1, 0.0, 0.0], "world", 1.0)


def test_an_implausible_reading_stops_the_arm(profile: RobotProfile) -> None:
    arm, position, robot = _rig(profile)
    robot.run_until(0.5)
    arm.move_to(profile.arm.poses["look_forward"], 0.5, "look_forward")  # type: ignore[union-attr]
    velocities = arm.update(0.55)
    assert velocities
    robot.send(Command(velocities=velocities))
    position.faults["elbow"] = "a jump the servo cannot make"
    assert arm.update(0.6) == {}
    assert not arm.active
    assert arm.pop_messages() == [
        "arm: move to look_forward stopped: elbow: its reading is implausible "
        "(a jump the servo cannot make)"
    ]


def test_speeds_below_the_servos_start_pulse_or_rest(profile: RobotProfile) -> None:
    arm, _, _ = _rig(profile)
    channel = arm.channels[1]
    floor = profile.channels[channel].min_speed
    assert arm._servo(channel, floor * 0.7) == floor
    assert arm._servo(channel, -floor * 0.6) == -floor
    assert arm._servo(channel, floor * 0.3) == 0.0
    assert arm._servo(channel, 50.0) == arm.limits.get(channel)


def test_the_prediction_knows_the_robot_keeps_the_waist_still_while_driving(
    profile: RobotProfile,
) -> None:
    """The robot refuses to turn a `locked_while_driving` channel while the chassis moves:
    the predictor must not count such a command as motion (the arm's feedback and its
    collision checks stand on that prediction)."""
    arm, position, robot = _rig(profile)
    robot.run_until(0.5)
    waist = robot.joints["waist"]
    command = {"drive_linear": 0.3, "waist": 0.3}
    robot.send(Command(velocities=command))
    position.note_sent(0.5, command)
    assert position.driving
    robot.run_until(1.5)
    assert robot.joints["waist"] == waist  # the simulator kept it still
    assert position.predictors["waist"].eventual(1.5) == pytest.approx(waist, abs=1e-3)
    with pytest.raises(ArmError, match="the chassis is driving: the robot does not turn the waist"):
        arm.plan_move(profile.arm.poses["look_back"], 1.5)  # type: ignore[union-attr]
    # Without the drive the waist command counts again.
    position.note_sent(1.5, {"waist": 0.3})
    assert not position.driving
    assert position.predictors["waist"].eventual(1.6) > waist + 0.02
