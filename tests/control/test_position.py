"""Position controller: logic on synthetic readings, then the real simulator under delay.

The synthetic tests drive a plain joint model (`DelayedJoint`: an integrator whose commands
and readings each take half the round trip) at the controller's own period, so every step is
deterministic; the last tests run the real simulator over UDP with latency and noise.
"""

from __future__ import annotations

import math
import random
from collections.abc import Iterator

import pytest

from ocu.control.commands import VelocityLimits
from ocu.control.position import (
    JointPredictor,
    PositionController,
    PositionError,
)
from ocu.link.live import UdpLink
from ocu.link.runner import PositionRunner
from ocu.profile import RobotProfile
from ocu.records import JointReading, LinkEvent, TelemetryFrame
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator, StateRecorder

PERIOD_S = 0.02


def reading(name: str, angle_rad: float, fault: str | None = None) -> JointReading:
    return JointReading(name, 0, 1, 2, angle_rad, 0.0, 0.0, 0, angle_rad, 0.0, 0.0, fault)


@pytest.fixture
def controller(profile: RobotProfile) -> PositionController:
    return PositionController(profile, VelocityLimits(profile))


class DelayedJoint:
    """One joint as the robot moves it: commands land, and readings arrive, delay/2 later."""

    def __init__(
        self, joint: str, angle_rad: float, delay_s: float, noise_rad: float = 0.0, seed: int = 1
    ) -> None:
        self.joint = joint
        self.angle_rad = angle_rad
        self.delay_s = delay_s
        self.noise_rad = noise_rad
        self.rng = random.Random(seed)
        self.sent: list[tuple[float, float]] = []  # (landing time, velocity)
        self.readings: list[tuple[float, float]] = []  # (arrival time, angle)
        self.velocity = 0.0
        self.time_s = 0.0
        self.peak_rad = angle_rad

    def send(self, now: float, velocity: float) -> None:
        self.sent.append((now + self.delay_s / 2, velocity))

    def advance(self, now: float, telemetry_period_s: float) -> list[float]:
        """Move to `now`; the angles of the readings that arrive by then."""
        while self.time_s < now - 1e-12:
            step = min(PERIOD_S / 4, now - self.time_s)
            while self.sent and self.sent[0][0] <= self.time_s:
                self.velocity = self.sent.pop(0)[1]
            self.angle_rad += self.velocity * step
            self.peak_rad = max(self.peak_rad, self.angle_rad)
            previous = self.time_s
            self.time_s += step
            if math.floor(self.time_s / telemetry_period_s) > math.floor(
                previous / telemetry_period_s
            ):
                noise = self.rng.uniform(-self.noise_rad, self.noise_rad)
                self.readings.append((self.time_s + self.delay_s / 2, self.angle_rad + noise))
        arrived = [angle for at, angle in self.readings if at <= now]
        self.readings = [(at, angle) for at, angle in self.readings if at > now]
        return arrived


def run(
    controller: PositionController,
    plant: DelayedJoint,
    target_rad: float,
    telemetry_period_s: float,
    duration_s: float,
    *,
    measured_delay_s: float | None = None,
) -> list[str]:
    """Control the plant to a target; the controller's messages."""
    delay = plant.delay_s if measured_delay_s is None else measured_delay_s
    now = 0.0
    controller.on_telemetry({plant.joint: reading(plant.joint, plant.angle_rad)}, now, delay)
    controller.set_target(plant.joint, target_rad)
    channel = controller.channel_of(plant.joint)
    messages: list[str] = []
    while now < duration_s:
        for angle in plant.advance(now, telemetry_period_s):
            controller.on_telemetry({plant.joint: reading(plant.joint, angle)}, now, delay)
        velocity = controller.update(now).get(channel, 0.0)
        controller.note_sent(now, {channel: velocity})
        plant.send(now, velocity)
        messages += controller.pop_messages()
        if not controller.targets and plant.velocity == 0.0 and not plant.sent:
            break
        now += PERIOD_S
    return messages


# ---- the control law ---------------------------------------------------------------------


def test_speed_is_proportional_bounded_and_lifted(controller: PositionController) -> None:
    v_max = controller.limits.get("waist")
    controller.on_telemetry({"waist": reading("waist", 0.0)}, 0.0)
    controller.set_target("waist", 1.0)
    assert controller.update(0.0)["waist"] == pytest.approx(v_max)  # far: saturated
    controller.set_target("waist", -0.02)
    assert controller.update(0.0)["waist"] == pytest.approx(-controller.gain_per_s * 0.02)
    controller.set_target("waist", math.radians(0.1))
    assert controller.update(0.0)["waist"] == 0.0  # inside tolerance


def test_slow_gain_is_lifted_to_the_servo_minimum(profile: RobotProfile) -> None:
    controller = PositionController(profile, VelocityLimits(profile), max_gain_per_s=1.5)
    controller.on_telemetry({"waist": reading("waist", 0.0)}, 0.0)
    controller.set_target("waist", 0.008)
    assert controller.update(0.0)["waist"] == pytest.approx(profile.channels["waist"].min_speed)


def test_gain_shrinks_as_the_delay_grows(controller: PositionController) -> None:
    assert controller.gain_per_s == controller.max_gain_per_s
    controller.on_telemetry({"waist": reading("waist", 0.0)}, 0.0, delay_s=0.4)
    assert controller.gain_per_s == pytest.approx(controller.gain_delay_product / 0.4)
    assert controller.gain_per_s * 0.4 <= controller.gain_delay_product


def test_one_period_never_carries_past_the_target(controller: PositionController) -> None:
    controller.on_telemetry({"waist": reading("waist", 0.0)}, 0.0)
    controller.update(0.0)
    controller.update(0.5)  # the caller runs the controller at a slow 2 Hz
    controller.set_target("waist", 0.03)
    velocity = controller.update(1.0)["waist"]
    assert velocity > 0
    assert velocity * 0.5 <= 0.03


# ---- the prediction ----------------------------------------------------------------------


def test_the_estimate_counts_commands_still_in_flight() -> None:
    predictor = JointPredictor()
    predictor.command(0.0, 0.5)  # 0.5 rad/s from t = 0
    # A reading that arrives at t = 1.0 after a 0.4 s round trip was taken when the commands
    # of t <= 0.6 had landed: 0.3 rad of motion, and 0.2 rad more are already on their way.
    predictor.on_reading(0.3, received_at=1.0, delay_s=0.4)
    assert predictor.eventual(1.0) == pytest.approx(0.5)
    assert predictor.current(1.0, 0.4) == pytest.approx(0.4)  # half the round trip landed
    predictor.command(1.0, 0.0)
    assert predictor.eventual(2.0) == pytest.approx(0.5)


def test_noisy_readings_of_a_still_joint_are_averaged() -> None:
    predictor = JointPredictor()
    rng = random.Random(3)
    noise = math.radians(1.0)
    for k in range(60):
        predictor.on_reading(1.0 + rng.uniform(-noise, noise), received_at=float(k), delay_s=0.1)
    assert predictor.noise_rad == pytest.approx(noise / math.sqrt(3), rel=0.5)
    assert predictor.eventual(60.0) == pytest.approx(1.0, abs=math.radians(0.3))
    assert predictor.sigma_rad < math.radians(0.2)


def test_a_joint_that_ran_fast_is_found_where_it_stopped() -> None:
    predictor = JointPredictor()
    predictor.on_reading(0.0, 0.0, 0.0)
    predictor.command(0.0, 1.0)
    # The servo ran 20 % fast. A reading of the moving joint weighs less (its delay may be
    # off), but pulls the estimate toward itself...
    predictor.on_reading(0.6, 0.5, 0.0)
    assert 0.5 < predictor.eventual(0.5) < 0.6
    predictor.command(0.5, 0.0)
    # ... and readings of the stopped joint settle it.
    predictor.on_reading(0.6, 0.7, 0.0)
    assert predictor.eventual(0.7) == pytest.approx(0.6, abs=0.005)


# ---- reached, stale, stalled, limits -----------------------------------------------------


def test_reached_only_after_a_reading_taken_after_the_stop(controller: PositionController) -> None:
    controller.on_telemetry({"elbow": reading("elbow", 0.0)}, 0.0, delay_s=0.2)
    controller.set_target("elbow", 0.2)
    t = 0.0
    while (velocity := controller.update(t).get("elbow", 0.0)) != 0.0:
        controller.note_sent(t, {"elbow": velocity})
        t += PERIOD_S
    controller.note_sent(t, {"elbow": 0.0})
    stopped_at = t
    assert "elbow" in controller.targets  # predicted there, not yet measured
    # A reading that arrives 0.1 s after the stop was taken before the stop landed.
    before_stop = controller.predictors["elbow"].integral(stopped_at - 0.1)
    assert before_stop < 0.2
    controller.on_telemetry({"elbow": reading("elbow", before_stop)}, stopped_at + 0.1, delay_s=0.2)
    controller.update(stopped_at + 0.1)
    assert "elbow" in controller.targets
    controller.on_telemetry({"elbow": reading("elbow", 0.2)}, stopped_at + 0.25, delay_s=0.2)
    controller.update(stopped_at + 0.26)
    assert controller.targets == {}
    assert controller.pop_messages() == ["elbow: reached 11.5°"]


@pytest.mark.parametrize(("delay_s", "telemetry_hz"), [(0.2, 10.0), (0.4, 10.0), (0.4, 1.0)])
def test_no_overshoot_and_a_true_reached_under_delay(
    controller: PositionController, delay_s: float, telemetry_hz: float
) -> None:
    plant = DelayedJoint("shoulder", math.radians(10.0), delay_s)
    target = math.radians(60.0)
    messages = run(controller, plant, target, 1.0 / telemetry_hz, 20.0)
    assert messages == ["shoulder: reached 60.0°"]
    assert math.degrees(plant.peak_rad - target) <= 0.5
    assert math.degrees(abs(plant.angle_rad - target)) <= 0.5


def test_a_joint_too_noisy_to_confirm_gives_up_with_a_message(profile: RobotProfile) -> None:
    # ±3.3° of noise: the target ends either confirmed (the average of many still readings
    # puts it in the band) or with a message; never by hunting on until the console closes.
    for seed in range(1, 5):
        plant = DelayedJoint("shoulder", 0.0, 0.2, noise_rad=math.radians(3.3), seed=seed)
        controller = PositionController(profile, VelocityLimits(profile))
        messages = run(controller, plant, math.radians(30.0), 0.1, 60.0)
        assert len(messages) == 1, messages
        error_deg = math.degrees(abs(plant.angle_rad - math.radians(30.0)))
        if "reached" in messages[0]:
            assert error_deg <= 0.5
        else:
            assert "without confirming" in messages[0]
            assert "readings scatter" in messages[0]
            assert error_deg < 2.0


def test_stale_telemetry_stops_with_message(
    profile: RobotProfile, controller: PositionController
) -> None:
    controller.on_telemetry({"neck": reading("neck", 0.0)}, 0.0)
    controller.set_target("neck", 1.0)
    assert controller.update(1.0)["neck"] > 0
    stale = controller.stale_after_s
    assert stale == pytest.approx(2.5 / profile.link.telemetry_rate_hz)
    assert "neck" not in controller.update(stale + 1.1)  # finished: the caller zeroes it
    assert controller.targets == {}
    assert controller.pop_messages()[0].startswith("neck: stopped, telemetry stale")


def test_joint_that_does_not_move_is_stopped(controller: PositionController) -> None:
    controller.on_telemetry({"waist": reading("waist", 0.0)}, 0.0)
    controller.set_target("waist", 2.0)
    t = 0.0
    for packet in range(1, 3):
        while t < packet:
            controller.note_sent(t, controller.update(t))
            t += PERIOD_S
        controller.on_telemetry({"waist": reading("waist", 0.0)}, t)  # never moves
    assert controller.targets == {}
    assert "does not move as commanded" in controller.pop_messages()[0]


def test_a_late_reading_is_no_stall(controller: PositionController) -> None:
    # With a 0.4 s round trip the first readings after the start show no motion yet: they
    # were taken before the commands landed. That is not a stall.
    plant = DelayedJoint("waist", 0.0, 0.4)
    messages = run(controller, plant, 1.5, 0.1, 15.0)
    assert messages == ["waist: reached 85.9°"]


def test_implausible_reading_stops_the_joint_and_refuses_targets(
    controller: PositionController,
) -> None:
    controller.on_telemetry({"shoulder": reading("shoulder", 0.5)}, 0.0)
    controller.set_target("shoulder", 1.5)
    assert controller.update(0.0)["shoulder"] > 0
    fault = "raw position 0x00000000"
    controller.on_telemetry({"shoulder": reading("shoulder", -205888.0, fault)}, 0.1)
    assert controller.update(0.1).get("shoulder", 0.0) == 0.0
    assert controller.targets == {}
    assert "reading implausible" in controller.pop_messages()[0]
    with pytest.raises(PositionError, match="implausible"):
        controller.set_target("shoulder", 1.0)
    assert "shoulder" not in controller.predicted_angles(0.2)
    controller.on_telemetry({"shoulder": reading("shoulder", 0.5)}, 0.2)
    controller.set_target("shoulder", 1.0)  # plausible again


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


@pytest.fixture
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    simulator = RobotSimulator(profile, telemetry_hz=1.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


def control_in_sim(
    profile: RobotProfile, sim: RobotSimulator, targets_deg: dict[str, float], timeout_s: float
) -> tuple[list[str], StateRecorder]:
    controller = PositionController(profile, VelocityLimits(profile))
    link = UdpLink(profile, sim.address, gui_alive_timeout_s=None)
    runner = PositionRunner(controller, link)
    link.subscribe(runner.on_link_event)
    link.start()
    truth = StateRecorder(sim)
    try:
        assert sim.wait_until(lambda s: s.telemetry_sent >= 2, 5.0)
        for name, deg in targets_deg.items():
            controller.set_target(name, math.radians(deg))
        result = runner.run(timeout_s=timeout_s)
    finally:
        truth.stop()
        link.shutdown()
    assert result.finished, result.messages
    return result.messages, truth


def check_arrived(
    sim: RobotSimulator, truth: StateRecorder, targets_deg: dict[str, float], messages: list[str]
) -> None:
    assert sorted(m.split(":")[0] for m in messages) == sorted(targets_deg)
    assert all("reached" in m for m in messages), messages
    final = sim.state().joints_rad
    for name, deg in targets_deg.items():
        assert math.degrees(final[name]) == pytest.approx(deg, abs=0.5), name
        peak = max(math.degrees(s.joints_rad[name]) * math.copysign(1, deg) for s in truth.samples)
        assert peak <= abs(deg) + 1.0, f"{name} overshot to {peak:.2f}°"


@pytest.mark.slow
def test_reaches_four_targets_at_1hz_without_oscillating(
    profile: RobotProfile, sim: RobotSimulator
) -> None:
    targets_deg = {"waist": 60.0, "shoulder": 45.0, "elbow": -50.0, "neck": 30.0}
    messages, truth = control_in_sim(profile, sim, targets_deg, 20.0)
    check_arrived(sim, truth, targets_deg, messages)


@pytest.mark.slow
def test_reaches_targets_over_a_slow_noisy_link(profile: RobotProfile) -> None:
    # The field: 200 ms each way, 10 Hz telemetry, ±0.5° reading noise. Today's main
    # overshot or gave up "does not move as commanded" here.
    faults = FaultConfig(latency_ms=200.0)
    sim = RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0, faults=faults, seed=7,
                         noise_deg=0.5)  # fmt: skip
    sim.start()
    try:
        targets_deg = {"shoulder": 60.0, "elbow": -40.0}
        messages, truth = control_in_sim(profile, sim, targets_deg, 25.0)
        check_arrived(sim, truth, targets_deg, messages)
    finally:
        sim.stop()


class InjectWhenMoving:
    """Forwards telemetry; once the shoulder reads past an angle, its encoder breaks."""

    def __init__(self, runner: PositionRunner, sim: RobotSimulator, past_rad: float) -> None:
        self.runner = runner
        self.sim = sim
        self.past_rad = past_rad
        self.broken = False

    def __call__(self, event: LinkEvent) -> None:
        if isinstance(event, TelemetryFrame):
            shoulder = event.readings.get("shoulder")
            moved = shoulder is not None and (shoulder.angle_rad or 0) > self.past_rad
            if not self.broken and moved:
                self.broken = True
                self.sim.set_raw_position("shoulder", 0)
        self.runner.on_link_event(event)


@pytest.mark.slow
def test_a_broken_encoder_never_drives_the_joint_the_wrong_way(profile: RobotProfile) -> None:
    # Today's main drove the shoulder from 30° toward -2.9° on a raw reading of 0.
    sim = RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0,
                         initial_joints={"shoulder": math.radians(30)})  # fmt: skip
    sim.start()
    controller = PositionController(profile, VelocityLimits(profile))
    link = UdpLink(profile, sim.address, gui_alive_timeout_s=None)
    runner = PositionRunner(controller, link)
    listener = InjectWhenMoving(runner, sim, math.radians(40))
    link.subscribe(listener)
    link.start()
    truth = StateRecorder(sim)
    try:
        assert sim.wait_until(lambda s: s.telemetry_sent >= 2, 5.0)
        controller.set_target("shoulder", math.radians(100))
        result = runner.run(timeout_s=10.0)
        lowest = min(math.degrees(s.joints_rad["shoulder"]) for s in truth.samples)
        with pytest.raises(PositionError, match=r"implausible .*0x00000000"):
            controller.set_target("shoulder", math.radians(60))
    finally:
        truth.stop()
        link.shutdown()
        sim.stop()
    assert listener.broken
    assert result.finished
    assert len(result.messages) == 1
    assert "reading implausible" in result.messages[0]
    assert "zero_offset_ticks" in result.messages[0]
    assert lowest >= 29.9
    assert math.degrees(sim.state().joints_rad["shoulder"]) < 60  # stopped soon after


@pytest.mark.slow
def test_reordered_telemetry_does_not_pull_the_estimate_back(profile: RobotProfile) -> None:
    # 150 ms of jitter at 10 Hz telemetry reorders packets; main peaked at 67.4° for 60°.
    faults = FaultConfig(latency_ms=50.0, jitter_ms=150.0)
    sim = RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0, faults=faults, seed=3,
                         initial_joints={"shoulder": math.radians(10)})  # fmt: skip
    sim.start()
    try:
        messages, truth = control_in_sim(profile, sim, {"shoulder": 60.0}, 20.0)
        check_arrived(sim, truth, {"shoulder": 60.0}, messages)
    finally:
        sim.stop()


@pytest.mark.slow
def test_readings_too_noisy_to_confirm_end_the_target(profile: RobotProfile) -> None:
    # ±3.3° of reading noise: main hunted until the console closed.
    sim = RobotSimulator(profile, telemetry_hz=10.0, video_fps=0.0, noise_deg=3.3, seed=4)
    sim.start()
    try:
        controller = PositionController(profile, VelocityLimits(profile))
        link = UdpLink(profile, sim.address, gui_alive_timeout_s=None)
        runner = PositionRunner(controller, link)
        link.subscribe(runner.on_link_event)
        link.start()
        try:
            assert sim.wait_until(lambda s: s.telemetry_sent >= 2, 5.0)
            controller.set_target("elbow", math.radians(40))
            result = runner.run(timeout_s=30.0)
        finally:
            link.shutdown()
        assert result.finished, "the target never ended"
        assert len(result.messages) == 1
        assert math.degrees(sim.state().joints_rad["elbow"]) == pytest.approx(40, abs=2.0)
    finally:
        sim.stop()


# ---- late ticks (a busy caller: the console's GUI thread under load) -----------------------

# Tick intervals as measured on the console's GUI thread beside two CPU-bound processes
# (issue 21): mostly on time, then one or two far late.
LATE_TICKS_S = (0.05, 0.05, 0.3, 0.05, 0.2, 0.05, 0.05, 0.05, 0.35, 0.1)


@pytest.mark.parametrize(
    ("joint", "start_deg", "target_deg", "telemetry_hz"),
    [("neck", 0.0, 15.0, 1.0), ("waist", 0.0, 25.0, 1.0), ("elbow", 0.0, -30.0, 10.0)],
)
def test_late_irregular_ticks_never_drive_a_joint_back(
    controller: PositionController,
    joint: str,
    start_deg: float,
    target_deg: float,
    telemetry_hz: float,
) -> None:
    # The command chosen at one tick stays on the wire until the next; with ticks late by
    # up to 0.35 s, main sized it for the last interval, ran the joint past the target and
    # drove it back on the prediction (what tests/windows' 1 Hz test saw under load).
    plant = DelayedJoint(joint, math.radians(start_deg), 0.08)
    target = math.radians(target_deg)
    channel = controller.channel_of(joint)
    now = 0.0
    controller.on_telemetry({joint: reading(joint, plant.angle_rad)}, now, plant.delay_s)
    controller.set_target(joint, target)
    sent: list[float] = []
    period = 1.0 / telemetry_hz
    for step in range(400):
        # Readings are stamped when they arrive (the link's thread), handled at the tick.
        arrived = now - LATE_TICKS_S[(step - 1) % len(LATE_TICKS_S)] if step else now
        while arrived < now - 1e-9:
            arrived = min(arrived + 0.005, now)
            for angle in plant.advance(arrived, period):
                controller.on_telemetry({joint: reading(joint, angle)}, arrived, plant.delay_s)
        velocity = controller.update(now).get(channel, 0.0)
        controller.note_sent(now, {channel: velocity})
        plant.send(now, velocity)
        sent.append(velocity)
        if not controller.targets:
            break
        now += LATE_TICKS_S[step % len(LATE_TICKS_S)]
    assert controller.pop_messages() == [f"{joint}: reached {target_deg:.1f}°"]
    direction = math.copysign(1.0, target_deg)
    assert all(v * direction >= 0.0 for v in sent), "driven back past the target"
    overshoot = (plant.angle_rad - target) * direction
    assert math.degrees(overshoot) <= 0.5
    assert math.degrees(abs(plant.angle_rad - target)) <= 0.5


def test_a_reversal_waits_for_a_reading_taken_after_the_stop(
    controller: PositionController,
) -> None:
    # The prediction says the joint ran 0.05 rad past its target (a servo faster than
    # modelled, a tick later than the horizon): it stops, and goes back only on a reading.
    controller.on_telemetry({"elbow": reading("elbow", 0.0)}, 0.0, delay_s=0.2)
    controller.set_target("elbow", 0.2)
    assert controller.update(0.0)["elbow"] > 0.0
    controller.note_sent(0.0, {"elbow": 0.5})  # sent by hand: 0.5 rad/s for 0.5 s
    assert controller.update(0.5)["elbow"] == 0.0  # eventual 0.25: past, not yet seen
    controller.note_sent(0.5, {"elbow": 0.0})
    assert controller.update(0.6)["elbow"] == 0.0
    # A reading taken after the stop landed (0.5 + 0.1 s) shows it past: now it goes back.
    controller.on_telemetry({"elbow": reading("elbow", 0.25)}, 0.85, delay_s=0.2)
    assert controller.update(0.85)["elbow"] < 0.0


def test_a_motion_ends_at_the_target_when_the_next_tick_never_comes(
    controller: PositionController,
) -> None:
    # On a loaded machine the next tick may come a second late: the command chosen now says
    # when the joint reaches the target, the link ends it then (Command.until), and the
    # prediction knows it - the late tick finds the joint at the target, not past it.
    controller.on_telemetry({"elbow": reading("elbow", 0.0)}, 0.0, delay_s=0.2)
    controller.set_target("elbow", 0.2)
    velocity = controller.update(0.0)["elbow"]
    until = controller.until["elbow"]
    assert velocity > 0.0
    assert velocity * until == pytest.approx(0.2)  # the travel until the end is the error
    controller.note_sent(0.0, {"elbow": velocity}, controller.until)
    assert controller.predictors["elbow"].eventual(until + 1.0) == pytest.approx(0.2)
    assert controller.update(until + 1.0) == {"elbow": 0.0}  # holding: not past, not back
    controller.note_sent(until + 1.0, {"elbow": 0.0})
    for k in range(1, 6):  # a few readings where it stopped confirm it
        controller.on_telemetry({"elbow": reading("elbow", 0.2)}, until + 1.0 + k, delay_s=0.2)
        controller.update(until + 1.0 + k)
    assert controller.pop_messages() == ["elbow: reached 11.5°"]


def test_a_newer_command_before_the_end_replaces_it_in_the_prediction() -> None:
    predictor = JointPredictor()
    predictor.command(0.0, 1.0, until=1.0)
    assert predictor.integral(5.0) == pytest.approx(1.0)
    predictor.command(0.5, 1.0)  # the same speed, no end: runs on
    assert predictor.integral(2.0) == pytest.approx(2.0)
    predictor.command(2.0, -1.0, until=2.25)
    assert predictor.integral(5.0) == pytest.approx(1.75)
    assert predictor.last_change_at == 2.25  # the end is a change: readings must follow it
