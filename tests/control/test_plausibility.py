"""Implausible joint readings are named, with the profile keys that most likely hold the error."""

from __future__ import annotations

import math

from ocu.control.plausibility import PlausibilityChecker
from ocu.profile import RobotProfile
from ocu.protocol import MotorRecord, TelemetryPacket
from ocu.protocol.mapping import rad_to_ticks, read_telemetry

SHOULDER_ID = 5


def packet(profile: RobotProfile, tick: int, raw: int) -> TelemetryPacket:
    return TelemetryPacket(tick=tick, motors=(MotorRecord(device_id=SHOULDER_ID, position=raw),))


def judge(checker: PlausibilityChecker, profile: RobotProfile, tick: int, raw: int) -> str | None:
    telemetry = packet(profile, tick, raw)
    return checker.check(telemetry, read_telemetry(profile, telemetry)).get("shoulder")


def degrees_raw(profile: RobotProfile, angle_deg: float) -> int:
    return rad_to_ticks(profile.motors["shoulder"], math.radians(angle_deg))


def test_readings_inside_the_limits_are_plausible(profile: RobotProfile) -> None:
    checker = PlausibilityChecker(profile)
    assert judge(checker, profile, 1000, degrees_raw(profile, 30.0)) is None
    assert judge(checker, profile, 2000, degrees_raw(profile, 50.0)) is None  # 20°/s is fine
    assert judge(checker, profile, 3000, degrees_raw(profile, 123.0)) is None  # within margin


def test_an_empty_encoder_names_the_offset(profile: RobotProfile) -> None:
    checker = PlausibilityChecker(profile)
    for raw in (0, 0xFFFFFFFF):
        fault = judge(checker, profile, 1000, raw)
        assert fault is not None
        assert f"raw position 0x{raw:08x}" in fault
        assert "motors.shoulder.zero_offset_ticks" in fault


def test_a_far_reading_names_offset_and_scale(profile: RobotProfile) -> None:
    checker = PlausibilityChecker(profile)
    fault = judge(checker, profile, 1000, degrees_raw(profile, 200.0))
    assert fault is not None
    assert "200.0° is outside the limits [-10°, 120°]" in fault
    assert "zero_offset_ticks" in fault
    assert "ticks_per_rad" in fault


def test_a_jump_faster_than_the_joint_is_implausible_until_time_allows_it(
    profile: RobotProfile,
) -> None:
    checker = PlausibilityChecker(profile)
    assert judge(checker, profile, 1000, degrees_raw(profile, 0.0)) is None
    fault = judge(checker, profile, 1100, degrees_raw(profile, 100.0))  # 100° in 0.1 s
    assert fault is not None
    assert "faster than the joint can" in fault
    assert "ticks_per_rad" in fault
    # Judged against the last plausible reading, not the glitch:
    assert judge(checker, profile, 1200, degrees_raw(profile, 1.0)) is None
    # A joint that really moved while its readings were bad is believed again in time.
    assert judge(checker, profile, 1300, degrees_raw(profile, 100.0)) is not None
    assert judge(checker, profile, 60000, degrees_raw(profile, 100.0)) is None


def test_reset_forgets_the_baseline(profile: RobotProfile) -> None:
    checker = PlausibilityChecker(profile)
    judge(checker, profile, 1000, degrees_raw(profile, 0.0))
    checker.reset()
    assert judge(checker, profile, 1100, degrees_raw(profile, 100.0)) is None
