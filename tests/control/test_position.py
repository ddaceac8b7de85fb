"""Position controller: logic on synthetic readings, then the real simulator at 1 Hz telemetry."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest

from ocu.control.commands import JointReading, VelocityLimits
from ocu.control.position import PositionController, PositionError
from ocu.control.runner import PositionRunner
from ocu.link.core import LinkCore, LinkListener, TelemetryFrame
from ocu.profile import RobotProfile
from ocu.sim.simulator import RobotSimulator, StateRecorder


def reading(name: str, angle_rad: float) -> JointReading:
    return JointReading(name, 0, 1, 2, angle_rad, 0.0, 0.0, 0, angle_rad, 0.0, 0.0)


@pytest.fixture
def controller(profile: RobotProfile) -> PositionController:
    return PositionController(profile, VelocityLimits(profile))


def test_speed_is_proportional_bounded_and_lifted(
    profile: RobotProfile, controller: PositionController
) -> None:
    v_max = controller.limits.get("waist")
    controller.on_telemetry({"waist": reading("waist", 0.0)}, 0.0)
    controller.set_target("waist", 1.0)
    assert controller.update(0.0)["waist"] == pytest.approx(v_max)  # far: saturated
    controller.set_target("waist", -0.02)
    assert controller.update(0.0)["waist"] == pytest.approx(-controller.gain_per_s * 0.02)
    controller.set_target("waist", math.radians(0.1))
    assert controller.update(0.0)["waist"] == 0.0  # inside tolerance


def test_slow_gain_is_lifted_to_the_servo_minimum(profile: RobotProfile) -> None:
    controller = PositionController(profile, VelocityLimits(profile), gain_per_s=1.5)
    controller.on_telemetry({"waist": reading("waist", 0.0)}, 0.0)
    controller.set_target("waist", 0.008)
    assert controller.update(0.0)["waist"] == pytest.approx(profile.channels["waist"].min_speed)


def test_one_period_never_carries_past_the_target(controller: PositionController) -> None:
    controller.on_telemetry({"waist": reading("waist", 0.0)}, 0.0)
    controller.update(0.0)
    controller.update(0.5)  # the caller runs the controller at a slow 2 Hz
    controller.set_target("waist", 0.03)
    velocity = controller.update(1.0)["waist"]
    assert velocity > 0
    assert velocity * 0.5 <= 0.03


def test_prediction_between_packets_and_correction(controller: PositionController) -> None:
    controller.on_telemetry({"shoulder": reading("shoulder", 0.0)}, 10.0)
    controller.set_target("shoulder", 1.5)
    v = controller.update(10.0)["shoulder"]
    controller.update(10.5)
    assert controller.predicted_angle("shoulder") == pytest.approx(v * 0.5)
    controller.on_telemetry({"shoulder": reading("shoulder", 0.1)}, 10.6)
    assert controller.predicted_angle("shoulder") == pytest.approx(0.1)


def test_reached_only_after_telemetry_confirms(controller: PositionController) -> None:
    controller.on_telemetry({"elbow": reading("elbow", 0.0)}, 0.0)
    controller.set_target("elbow", 0.2)
    t = 0.0
    while controller.update(t).get("elbow", 0.0) != 0.0:
        t += 0.02
    assert "elbow" in controller.targets  # predicted there, not yet measured
    controller.on_telemetry({"elbow": reading("elbow", 0.19)}, t)
    assert controller.update(t + 0.02)["elbow"] > 0  # measured short: corrects
    controller.on_telemetry({"elbow": reading("elbow", 0.2)}, t + 0.1)
    assert controller.targets == {}
    assert controller.pop_messages() == ["elbow: reached 11.5°"]


def test_stale_telemetry_stops_with_message(
    profile: RobotProfile, controller: PositionController
) -> None:
    controller.on_telemetry({"neck": reading("neck", 0.0)}, 0.0)
    controller.set_target("neck", 1.0)
    assert controller.update(1.0)["neck"] > 0
    stale = controller.stale_after_s
    assert stale == pytest.approx(2.5 / profile.link.telemetry_rate_hz)
    assert controller.update(stale + 0.1)["neck"] == 0.0
    assert controller.targets == {}
    assert controller.pop_messages()[0].startswith("neck: stopped, telemetry stale")


def test_joint_that_does_not_move_is_stopped(controller: PositionController) -> None:
    controller.on_telemetry({"waist": reading("waist", 0.0)}, 0.0)
    controller.set_target("waist", 2.0)
    t = 0.0
    for packet in range(1, 3):
        while t < packet:
            controller.update(t)
            t += 0.02
        controller.on_telemetry({"waist": reading("waist", 0.0)}, t)  # never moves
    assert controller.targets == {}
    assert "does not move as commanded" in controller.pop_messages()[0]


def test_limits(profile: RobotProfile, controller: PositionController) -> None:
    low, high = profile.motors["shoulder"].limits_rad or (0.0, 0.0)
    with pytest.raises(PositionError, match=r"shoulder: target 150\.0° outside the limits"):
        controller.set_target("shoulder", math.radians(150))
    with pytest.raises(PositionError, match="not a joint driven"):
        controller.set_target("left_track", 0.0)
    with pytest.raises(PositionError, match="not a joint driven"):
        controller.set_target("head_pan", 0.0)
    with pytest.raises(PositionError, match="finite"):
        controller.set_target("waist", math.nan)
    controller.on_telemetry({"shoulder": reading("shoulder", high)}, 0.0)
    controller.set_target("shoulder", high)
    controller.on_telemetry({"shoulder": reading("shoulder", high - 0.0001)}, 0.0)
    controller.set_target("shoulder", low)
    assert controller.update(0.0)["shoulder"] < 0  # moving away from a limit is fine


def test_several_joints_and_cancel(controller: PositionController) -> None:
    readings = {name: reading(name, 0.0) for name in ("waist", "shoulder", "elbow", "neck")}
    controller.on_telemetry(readings, 0.0)
    for name in readings:
        controller.set_target(name, 0.5)
    assert set(controller.update(0.0)) == {"waist", "shoulder", "elbow", "neck"}
    controller.cancel("elbow")
    assert set(controller.targets) == {"waist", "shoulder", "neck"}
    controller.cancel()
    assert controller.update(0.1) == {}


# ---- against the real simulator -----------------------------------------------------------


class Forward(LinkListener):
    def __init__(self, runner: PositionRunner) -> None:
        self.runner = runner

    def telemetry_received(self, frame: TelemetryFrame) -> None:
        self.runner.on_readings(frame.readings, frame.received_at)


@pytest.fixture
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    simulator = RobotSimulator(profile, telemetry_hz=1.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


@pytest.mark.slow
def test_reaches_four_targets_at_1hz_without_oscillating(
    profile: RobotProfile, sim: RobotSimulator
) -> None:
    targets_deg = {"waist": 60.0, "shoulder": 45.0, "elbow": -50.0, "neck": 30.0}
    controller = PositionController(profile, VelocityLimits(profile))
    link = LinkCore(profile, sim.address, gui_alive_timeout_s=None)
    runner = PositionRunner(controller, link)
    link.listener = Forward(runner)
    link.start()
    truth = StateRecorder(sim)
    try:
        assert sim.wait_until(lambda s: s.telemetry_sent >= 1, 3.0)
        for name, deg in targets_deg.items():
            controller.set_target(name, math.radians(deg))
        result = runner.run(timeout_s=20.0)
    finally:
        truth.stop()
        link.shutdown()
    assert result.finished, result.messages
    assert sorted(m.split(":")[0] for m in result.messages) == sorted(targets_deg)
    assert all("reached" in m for m in result.messages), result.messages
    final = sim.state().joints_rad
    for name, deg in targets_deg.items():
        assert math.degrees(final[name]) == pytest.approx(deg, abs=0.5), name
        peak = max(math.degrees(s.joints_rad[name]) * math.copysign(1, deg) for s in truth.samples)
        assert peak <= abs(deg) + 1.0, f"{name} overshot to {peak:.2f}°"
