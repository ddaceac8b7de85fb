"""A calibration's shared state and helpers: its configuration and result, the joints found,
commands with their safety checks, sampling and settling, and the first two steps (listen,
zero offsets). The later steps are in scan.py, sweep.py and guided.py; session.py runs them."""

from __future__ import annotations

import datetime as dt
import logging
import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from ocu.calibrate.fit import Fit, Run
from ocu.calibrate.guard import (
    CalibrationAbortedError,
    Deadman,
    DeadmanReleasedError,
    StopSignal,
)
from ocu.calibrate.observer import Sample, TelemetryLog
from ocu.calibrate.operator import Operator
from ocu.calibrate.probe import MISMATCH, Finding, median_interval_s
from ocu.calibrate.raw import raw_command, raw_profile, tick_delta
from ocu.link.base import Link
from ocu.profile import Motor, RobotProfile
from ocu.records import LinkState

log = logging.getLogger("ocu.calibrate")

POSITIVE = 1
NEGATIVE = -1
# A ticks-per-radian fit from the axis scan's short pulse is used (for the excursion guard
# and planning) only when known to this fraction.
ROUGH_FIT_ERROR = 0.15
# Ticks per radian of a 16-bit encoder per turn, for a joint the profile gives none.
DEFAULT_TICKS_PER_RAD = 65536 / (2 * math.pi)
# Scans of the axes, each with a longer wait, before a round trip is called unbounded.
MAX_SCANS = 3


@dataclass(frozen=True)
class CalibrationConfig:
    """How gently and how long the calibration moves (defaults: docs/calibration.md)."""

    # The automatic moves are planned within `planned_excursion_deg` of the start pose and
    # stopped beyond `max_excursion_deg` as the readings reckon it (noise and a lossy link
    # may hide a degree; the bound a calibration must keep is 10°).
    max_excursion_deg: float = 9.0
    planned_excursion_deg: float = 6.0
    # The axis value of the scan pulses: 0.04 rad/s at the profile's joint scale, at most
    # 0.08 rad/s for a joint scale half the profile's.
    scan_axis_value: int = 800
    joint_speed_rad_s: float = 0.1
    # Time allowed for a command to reach the robot and its effect to come back: this much
    # until the axis scan has measured the round trip (from the speed commands the robot
    # echoes), then 1.5 times the shortest round trip seen, and at least `min_margin_s`.
    latency_margin_s: float = 0.5
    min_margin_s: float = 0.12
    min_leg_s: float = 0.4
    # The link repeats the command this often during a calibration (at most the profile's
    # maximum). At the profile's 5 Hz a pulse shorter than 0.2 s rests on one datagram: lost,
    # or overtaken on the way by the zeros of the tick sent just before it (jitter reorders
    # datagrams; the robot obeys the last to arrive), the axis looks as if it drove nothing.
    command_rate_hz: float = 50.0
    # Noisy readings: runs long enough for this relative error each, never slower than this.
    noisy_run_error: float = 0.01
    min_sweep_speed_rad_s: float = 0.05
    max_sweep_cycles: int = 4
    # Sweeps repeat until ticks per radian is known to this fraction (1 sigma).
    target_relative_error: float = 0.005
    # Telemetry speeds within this many raw units of zero count as standing still.
    speed_noise_raw: int = 1
    settle_timeout_s: float = 4.0
    listen_s: float = 1.5
    min_listen_samples: int = 3
    known_angle_deg: float = 8.0
    limit_speed_rad_s: float = 0.15
    limit_margin_deg: float = 1.0
    limit_travel_deg: float = 360.0
    # A joint reported this many times faster than commanded is not believed.
    implausible_speed_factor: float = 3.0
    # A position jumping further than speed and time allow, plus this, is not believed.
    jump_allowance_deg: float = 3.0
    control_period_s: float = 0.02


@dataclass(frozen=True)
class Measured:
    """One profile key found by the calibration: its value and how it was found."""

    key: str
    value: Any
    how: str
    residual: float | None = None
    residual_unit: str | None = None
    samples: int | None = None


@dataclass
class CalibrationResult:
    """What a calibration found, what it could not, and how it went."""

    measured: dict[str, Measured] = field(default_factory=dict)
    findings: list[Finding] = field(default_factory=list)
    aborted: str | None = None
    started_at: dt.datetime = field(default_factory=lambda: dt.datetime.now(dt.UTC))
    duration_s: float = 0.0
    # The largest excursion of each joint from its start, as the calibration reckoned it.
    excursion_deg: dict[str, float] = field(default_factory=dict)

    def value(self, key: str) -> Any:
        """The measured value of a key (KeyError if it was not measured)."""
        return self.measured[key].value

    @property
    def complete(self) -> bool:
        """Nothing aborted and nothing contradicted."""
        return self.aborted is None and not any(f.level == MISMATCH for f in self.findings)


@dataclass
class _Joint:
    """What the calibration knows of one motor with a position."""

    motor: Motor
    device_id: int
    start_ticks: int
    noise_ticks: float
    ticks_per_rad: float | None = None
    channel: str | None = None
    axis: int | None = None
    sign: int = POSITIVE
    scan_speed_rad_s: float | None = None
    free: set[int] = field(default_factory=set)
    integrated_rad: float = 0.0
    excursion_rad: float = 0.0
    # Ticks per radian from the axis scan's pulse: rough, for the excursion guard only.
    rough_ticks_per_rad: float | None = None
    last: Sample | None = None
    # This device's reading in the zero pose; its key names the motor the device is (which
    # the guided mode may learn only after the zero step).
    zero: Measured | None = None


@dataclass(frozen=True)
class _Response:
    """What one device did while one axis was pulsed."""

    speed_raw: int
    command_raw: int
    moved_ticks: int

    def direction(self) -> int:
        """The sign of the motion (position first, then speed, then the command echo)."""
        for value in (self.moved_ticks, self.speed_raw, self.command_raw):
            if value:
                return POSITIVE if value > 0 else NEGATIVE
        return 0


class _RescanError(Exception):
    """The round trip is longer than the axis scan waited: it must start again."""

    def __init__(self, margin_s: float) -> None:
        super().__init__(f"round trip needs {margin_s:.2f} s")
        self.margin_s = margin_s


def _stated(fit: Fit) -> str:
    """A fit's expanded uncertainty as the operator reads it."""
    expanded = fit.expanded_uncertainty
    return "± unknown" if expanded is None else f"±{expanded * 100:.2f} %"


def _unknown_motor(device_id: int) -> Motor:
    """A stand-in for a device the profile does not know."""
    return Motor(
        name=f"device{device_id}",
        device_id=device_id,
        channel=None,
        track=None,
        ticks_per_rad=None,
        zero_offset_ticks=0,
        limits_rad=None,
    )


STEP_TEXT = {
    "listen": "Listening: telemetry, the motors, the noise of each position.",
    "zero": "Zero offsets: the robot must be in its zero pose (the 3D model's pose at 0°).",
    "axes": "Axis map: each of the 16 axes is pulsed in turn, a little, out and back.",
    "sweep": "Joint scales and ticks per radian: each joint sweeps a few degrees about its pose.",
    "known_angle": "Known angle: each joint moves about 8°; measure how far it really moved.",
    "limits": "Limits: slow moves to the hard stops of the joints you choose.",
    "drive": "Drive constants (seed 000 §3.1): drive a known distance at a few speeds and time it.",
}


class CalibratorCore:
    """A calibration's state and what every step uses: commands, safety checks, sampling,
    listening and zero offsets (ocu.calibrate.session.Calibrator runs the steps).

    The link must be new and not started: the calibrator subscribes, starts it and leaves
    the shutdown (zeros last) to its owner. `run()` blocks; call it on a thread of its own
    when a GUI waits.
    """

    def __init__(
        self,
        link: Link,
        profile: RobotProfile,
        operator: Operator,
        *,
        deadman: Deadman,
        stop: StopSignal,
        config: CalibrationConfig | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.link = link
        self.profile = profile
        self.raw = raw_profile(profile)
        self.operator = operator
        self.deadman = deadman
        self.stop = stop
        self.config = config or CalibrationConfig()
        self.clock = clock
        self.log = TelemetryLog(profile.link.telemetry_tick_hz)
        self.result = CalibrationResult()
        self.speed_scale = profile.telemetry_speed_per_rad_s
        # The robot reports speeds as integers of this unit: their resolution in rad/s.
        self.speed_step_rad_s = 1.0 / self.speed_scale
        self._joints: dict[int, _Joint] = {}
        self._devices: frozenset[int] = frozenset()
        self._moving = False
        self._allowed: set[int] | None = None
        self._expected_rad_s = self.config.joint_speed_rad_s
        self._checked = 0
        self._period_s = 1.0 / profile.link.telemetry_rate_hz
        self._axis_map: dict[str, tuple[int, int]] = {}
        self._listened: list[Sample] = []
        self._margin_s = self.config.latency_margin_s
        # Round trips seen: from a pulse's command to the first reading that echoes it.
        self._round_trips: list[float] = []
        # The last sample in which nothing moved, until the next motion command.
        self._settled: Sample | None = None
        # While searching hard stops the excursion budget does not apply (guided only).
        self._limit_search = False
        # Motor name -> the device whose zero-pose reading is that motor's zero offset.
        self._zero_owner: dict[str, int] = {}

    def _wait_for_deadman(self) -> None:
        self.log.wait(self.deadman.held, math.inf, self._poll_still)

    def _finding(self, level: str, text: str, key: str | None = None) -> None:
        self.result.findings.append(Finding(level, text, key))
        self.operator.say(("!! " if level == MISMATCH else "") + text)

    def _measure(self, item: Measured) -> None:
        self.result.measured[item.key] = item
        log.info("measured %s = %r (%s)", item.key, item.value, item.how)

    # ---- commands and safety -------------------------------------------------------------

    def _command(self, axes: dict[int, int]) -> None:
        moving = any(axes.values())
        if moving and not self.deadman.held():
            raise DeadmanReleasedError
        self._moving = moving
        if moving:
            self._settled = None
        self.link.set_command(raw_command(self.raw, axes))

    def _zero(self) -> None:
        self._moving = False
        self.link.set_command(raw_command(self.raw))

    def _poll_still(self) -> None:
        """Heartbeat and the checks that hold while nothing is commanded."""
        self.link.heartbeat()
        if self.stop.stopped:
            raise CalibrationAbortedError(self.stop.reason or "e-stop")
        if self.log.state in (LinkState.LOST, LinkState.CLOSED):
            raise CalibrationAbortedError(f"{self.log.state.label}: {self.log.state_reason}")
        self._check_samples()

    def _poll(self) -> None:
        """Everything `_poll_still` checks, and the deadman while moving."""
        self._poll_still()
        if self._moving and not self.deadman.held():
            self._zero()
            raise DeadmanReleasedError

    def _check_samples(self) -> None:
        """Judge the samples that arrived since the last call (implausible -> abort)."""
        samples = self.log.samples()
        count = self.log.count
        new = samples[len(samples) - min(count - self._checked, len(samples)) :]
        self._checked = count
        for sample in new:
            self._judge(sample)

    def _judge(self, sample: Sample) -> None:
        if self._devices and set(sample.motors) != self._devices:
            missing = sorted(self._devices - set(sample.motors))
            extra = sorted(set(sample.motors) - self._devices)
            raise CalibrationAbortedError(
                f"implausible telemetry: devices changed (gone {missing}, new {extra})"
            )
        noise = self.config.speed_noise_raw
        for device_id, record in sample.motors.items():
            speed_rad_s = abs(record.speed) / self.speed_scale
            if (
                self._allowed is not None
                and device_id not in self._allowed
                and abs(record.speed) > noise
            ):
                raise CalibrationAbortedError(
                    f"implausible: device {device_id} moves at {speed_rad_s:.3f} while only "
                    f"devices {sorted(self._allowed)} may"
                )
            limit = self.config.implausible_speed_factor * max(self._expected_rad_s, 0.05)
            joint = self._joints.get(device_id)
            if joint is None:
                continue
            if speed_rad_s > limit:
                raise CalibrationAbortedError(
                    f"implausible: the {joint.motor.name} reports {speed_rad_s:.3f} rad/s, "
                    f"more than {limit:.3f} for what was commanded"
                )
            self._track_excursion(joint, sample)

    def _track_excursion(self, joint: _Joint, sample: Sample) -> None:
        record = sample.motors[joint.device_id]
        previous = joint.last
        if previous is not None:
            dt_s = sample.robot_time_s - previous.robot_time_s
            if dt_s > 0:
                # Trapezoids: a speed that changed between two readings changed half-way.
                mean_raw = (previous.motors[joint.device_id].speed + record.speed) / 2
                joint.integrated_rad += mean_raw / self.speed_scale * dt_s
            known = joint.ticks_per_rad or joint.rough_ticks_per_rad
            if known is not None and dt_s > 0:
                jump = abs(
                    tick_delta(previous.motors[joint.device_id].position, record.position)
                ) / abs(known)
                allowed = max(
                    abs(record.speed), abs(previous.motors[joint.device_id].speed)
                ) / self.speed_scale * dt_s * self.config.implausible_speed_factor + math.radians(
                    self.config.jump_allowance_deg
                )
                if jump > allowed:
                    raise CalibrationAbortedError(
                        f"implausible: the {joint.motor.name}'s position jumped "
                        f"{math.degrees(jump):.1f}° in {dt_s:.2f} s"
                    )
        joint.last = sample
        ticks_per_rad = joint.ticks_per_rad or joint.rough_ticks_per_rad
        if ticks_per_rad is not None:
            away = abs(tick_delta(joint.start_ticks, record.position)) - joint.noise_ticks
            reach = max(0.0, away) / abs(ticks_per_rad)
        else:
            reach = abs(joint.integrated_rad)
        joint.excursion_rad = max(joint.excursion_rad, reach)
        if reach > math.radians(self.config.max_excursion_deg) and not self._limit_search:
            raise CalibrationAbortedError(
                f"the {joint.motor.name} is {math.degrees(reach):.1f}° from where it started, "
                f"beyond the {self.config.max_excursion_deg:g}° a calibration may move it"
            )

    def _wait_samples(self, since: float, count: int, timeout_s: float) -> list[Sample]:
        """Wait for `count` samples received at or after `since`; fewer at the deadline."""
        self.log.wait(lambda: len(self.log.samples(since)) >= count, timeout_s, self._poll)
        return self.log.samples(since)

    def _settle(self) -> Sample:
        """Zero, then wait for a sample taken after the zero reached the robot in which
        nothing moves; a motor still moving by then is implausible. Nothing commanded since
        the last settled sample: the newest sample at once."""
        self._zero()
        if self._settled is not None:
            latest = self.log.latest()
            return latest if latest is not None else self._settled
        zeroed = self.clock()
        deadline = self.config.settle_timeout_s + 3 * self._period_s
        noise = self.config.speed_noise_raw

        def still() -> bool:
            latest = self.log.latest()
            return (
                latest is not None
                and latest.received_at >= zeroed + self._margin_s
                and all(
                    abs(r.speed) <= noise and abs(r.speed_command) <= noise
                    for r in latest.motors.values()
                )
            )

        if not self.log.wait(still, deadline, self._poll_still):
            latest = self.log.latest()
            moving = (
                sorted(
                    d
                    for d, r in latest.motors.items()
                    if abs(r.speed) > noise or abs(r.speed_command) > noise
                )
                if latest is not None
                else []
            )
            raise CalibrationAbortedError(
                f"implausible: devices {moving} still move (or are commanded) {deadline:.1f} s "
                "after zeros were sent"
                if moving
                else f"no telemetry for {deadline:.1f} s after zeros were sent"
            )
        latest = self.log.latest()
        assert latest is not None
        self._settled = latest
        return latest

    def _legs(self, axis: int, legs: Sequence[tuple[int, float]]) -> list[float]:
        """Command the axis through legs of (value, seconds) back to back; zero at the end
        (also on any error). Returns the legs' start times."""
        starts: list[float] = []
        try:
            for value, duration_s in legs:
                start = self.clock()
                starts.append(start)
                self._command({axis: value})
                while self.clock() - start < duration_s:
                    self._poll()
                    self.stop.wait(min(self.config.control_period_s, duration_s))
        finally:
            self._zero()
        return starts

    # ---- steps ---------------------------------------------------------------------------

    def _listen(self) -> None:
        """Telemetry flows; which devices report; the noise of each position."""
        self.operator.say(STEP_TEXT["listen"])
        start = self.clock()
        timeout = self.config.listen_s + (self.config.min_listen_samples + 2) * self._period_s + 3
        self.log.wait(
            lambda: (
                len(self.log.samples(start)) >= self.config.min_listen_samples
                and self.clock() - start >= self.config.listen_s
            ),
            timeout,
            self._poll_still,
        )
        samples = self.log.samples(start)
        self._listened = samples
        if len(samples) < 2:
            raise CalibrationAbortedError(
                f"only {len(samples)} telemetry packet(s) in {self.clock() - start:.1f} s: "
                "run `ocu probe` first"
            )
        interval = median_interval_s(samples)
        if interval is not None:
            self._period_s = interval
        self._devices = frozenset(samples[-1].motors)
        for motor in self.profile.motors.values():
            if motor.device_id not in self._devices:
                self._finding(
                    MISMATCH,
                    f"the profile's {motor.name} (device {motor.device_id}) does not report",
                    f"motors.{motor.name}.device_id",
                )
        for device_id in sorted(self._devices):
            positions = [s.motors[device_id].position for s in samples if device_id in s.motors]
            known = self.profile.motor_by_device(device_id)
            if known is not None and known.track is not None:
                continue
            if known is None or known.has_position:
                spread = max(abs(tick_delta(positions[0], p)) for p in positions)
                joint = _Joint(
                    motor=known if known is not None else _unknown_motor(device_id),
                    device_id=device_id,
                    start_ticks=positions[-1],
                    noise_ticks=float(spread),
                )
                self._joints[device_id] = joint
        self.operator.say(
            f"{len(samples)} telemetry packets, one every {self._period_s:.2f} s; devices "
            f"{sorted(self._devices)}"
        )

    def _zero_offsets(self) -> None:
        """The pose now is the zero pose: each joint's raw position is its zero offset.

        Guided, the operator may have just put the robot in that pose: fresh readings are
        taken. With --yes the readings of the listening step are (nothing has moved since).
        """
        samples = self._listened
        if self.operator.guided:
            start = self.clock()
            self.log.wait(
                lambda: len(self.log.samples(start)) >= self.config.min_listen_samples,
                (self.config.min_listen_samples + 2) * self._period_s + 2,
                self._poll_still,
            )
            samples = self.log.samples(start) or samples
        how = (
            "the operator confirmed the zero pose"
            if self.operator.guided
            else "--yes: the pose at the start is the zero pose"
        )
        for joint in self._joints.values():
            positions = [s.motors[joint.device_id].position for s in samples]
            base = positions[0]
            middle = round(statistics.median(tick_delta(base, p) for p in positions))
            offset = (base + middle) % 2**32
            joint.start_ticks = offset
            joint.zero = Measured(
                "",
                offset,
                f"raw position in the zero pose, the median of {len(positions)} readings ({how})",
                residual=joint.noise_ticks,
                residual_unit="ticks (spread of the readings)",
                samples=len(positions),
            )
            self._record_zero(joint)

    def _record_zero(self, joint: _Joint) -> None:
        """The device's zero-pose reading as the zero offset of the motor it is."""
        name = joint.motor.name
        if joint.zero is None or name.startswith("device"):
            return
        self._measure(replace(joint.zero, key=f"motors.{name}.zero_offset_ticks"))
        self._zero_owner[name] = joint.device_id

    def _runs(self, joint: _Joint, samples: Sequence[Sample]) -> list[tuple[Run, int]]:
        """Runs of samples at one constant non-zero reported speed, each with its speed."""
        runs: list[tuple[Run, int]] = []
        times: list[float] = []
        positions: list[float] = []
        speed_raw = 0
        origin: int | None = None
        noise = self.config.speed_noise_raw

        def close() -> None:
            if times and speed_raw:
                runs.append(
                    (Run(tuple(times), tuple(positions), speed_raw / self.speed_scale), speed_raw)
                )

        for sample in samples:
            record = sample.motors.get(joint.device_id)
            if record is None:
                continue
            if origin is None:
                origin = record.position
            position = float(tick_delta(origin, record.position))
            if abs(record.speed) <= noise or record.speed != speed_raw:
                close()
                times, positions = [], []
                speed_raw = record.speed if abs(record.speed) > noise else 0
            if speed_raw:
                times.append(sample.robot_time_s)
                positions.append(position)
        close()
        return runs
