"""`ocu calibrate`: find a robot's wire facts by moving it a little, over any Link.

Steps (docs/calibration.md), each shown to the operator and confirmed in the guided mode:

1. *listen*: telemetry flows, the motors report, position noise is measured;
2. *zero offsets*: the pose now is the zero pose (the guided mode asks for it first);
3. *axis map*: each of the 16 RCP axes is pulsed in turn at a small value, out and back;
   the motor whose speed, echoed speed command or position answers, and with which sign,
   gives the channel -> axis map and each channel's `axis_sign`. Which joint a device is
   cannot be seen from the telemetry: the guided mode asks (a wrong device ID is found so);
4. *joint scale and ticks per radian*: each joint sweeps about where it stands; positions
   against the robot's clock within runs of constant reported speed give ticks per radian
   (`fit_ticks_per_rad`), commanded axis values against reported speeds the axis scale;
5. guided only: a move through a known angle the operator measures; slow moves to the hard
   stops (limits); seed 000 §3.1's drive runs (linear and rotation constants).

Safety: the calibrator moves only while the deadman is held (or the robot is on a stand),
heartbeats the link so a stalled calibrator is zeroed by the link itself, stops on an
e-stop, LINK LOST or an implausible reading (a device moving that should not, a joint past
its excursion budget, a speed it cannot have, a motor still moving after zeros), and sets
zero on every way out. Every automatic move is planned to stay within
`planned_excursion_deg` of where the joint started and is stopped at `max_excursion_deg`.
"""

from __future__ import annotations

import datetime as dt
import logging
import math
import statistics
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from ocu.calibrate.fit import Fit, FitError, Run, fit_through_origin, fit_ticks_per_rad
from ocu.calibrate.guard import (
    CalibrationAbortedError,
    Deadman,
    DeadmanReleasedError,
    StopSignal,
)
from ocu.calibrate.observer import Sample, TelemetryLog
from ocu.calibrate.operator import LINEAR, ROTATION, DrivePlan, Operator
from ocu.calibrate.probe import MISMATCH, NOTE, Finding, median_interval_s
from ocu.calibrate.raw import raw_command, raw_profile, tick_delta
from ocu.link.base import Link
from ocu.profile import AXIS_COUNT, AXIS_MAX, Motor, RobotProfile
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


class Calibrator:
    """One calibration over a link built on `raw_profile(profile)` (see the module docstring).

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

    # ---- life ----------------------------------------------------------------------------

    def run(self) -> CalibrationResult:
        """Run every step; never raises for what the robot does (see result.aborted)."""
        started = self.clock()
        self.link.subscribe(self.log)
        self.link.start()
        rate_hz = self.link.rate_hz
        self.link.set_rate_hz(min(self.config.command_rate_hz, self.profile.link.send_rate_max_hz))
        try:
            self._listen()
            self._step("zero", self._zero_offsets)
            self._step("axes", self._scan)
            self._step("sweep", self._sweeps)
            if self.operator.guided:
                self._step("known_angle", self._known_angles)
                self._step("limits", self._limits)
                self._step("drive", self._drive_constants)
        except (CalibrationAbortedError, EOFError) as err:
            self.result.aborted = str(err)
            self.link.emergency_stop(f"calibration: {err}")
            self.operator.say(f"STOPPED: {err}")
        except BaseException:
            self.link.emergency_stop("calibration failed")
            raise
        finally:
            self._zero()
            self.link.set_rate_hz(rate_hz)
            self.link.unsubscribe(self.log)
            self.result.duration_s = self.clock() - started
            self.result.excursion_deg = {
                j.motor.name: math.degrees(j.excursion_rad) for j in self._joints.values()
            }
        return self.result

    def _step(self, name: str, body: Callable[[], None]) -> None:
        """Run a step; a released deadman stops it (zeros) and it starts again when held."""
        text = STEP_TEXT[name]
        if not self.operator.confirm(name, text):
            self.operator.say(f"skipped: {text}")
            return
        self.operator.say(text)
        while True:
            try:
                body()
                return
            except DeadmanReleasedError:
                self._zero()
                self.operator.say("deadman released: stopped; hold it to run the step again")
                self._wait_for_deadman()
                self._settle()

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

    # ---- axis map ------------------------------------------------------------------------

    def _scan(self) -> None:
        """Pulse each axis in turn; map the channels from the motors that answer."""
        for attempt in range(MAX_SCANS):
            try:
                self._scan_axes()
                return
            except _RescanError as err:
                if attempt == MAX_SCANS - 1:
                    raise CalibrationAbortedError(
                        f"the round trip kept growing ({err.margin_s:.2f} s after "
                        f"{MAX_SCANS} scans): check the link with `ocu probe`"
                    ) from err
                self.operator.say(
                    f"the robot answers slowly (round trip up to {err.margin_s:.2f} s): "
                    "scanning again with a longer wait"
                )
                self._forget_scan()

    def _forget_scan(self) -> None:
        """Drop what a scan judged with too short a wait."""
        self._axis_map.clear()
        for key in [k for k in self.result.measured if k.startswith("channels.")]:
            del self.result.measured[key]
        # The findings of the axis scan (and of the devices the operator named in it).
        self.result.findings = [
            f for f in self.result.findings if not f.text.startswith(("axis ", "device "))
        ]
        for joint in self._joints.values():
            joint.channel = joint.axis = None
            joint.free.clear()
        self._round_trips.clear()

    def _scan_axes(self) -> None:
        silent = [axis for axis in range(AXIS_COUNT) if not self._scan_axis(axis)]
        missing = [name for name in self.profile.channels if name not in self._axis_map]
        if missing and silent:
            # A pulse can miss the robot (a burst of loss, a link that stalled): the axes
            # that seemed to drive nothing get a second pulse before a channel is given up.
            self.operator.say(
                f"no axis answered for {', '.join(missing)}: pulsing the silent axes again"
            )
            for axis in silent:
                self._scan_axis(axis)
        for name in self.profile.channels:
            if name not in self._axis_map:
                self._finding(
                    MISMATCH,
                    f"no axis moves the {name}: channels.{name}.axis stays an assumption",
                    f"channels.{name}.axis",
                )

    def _scan_axis(self, axis: int) -> bool:
        """Pulse one axis and map what answered; whether anything did."""
        responses = self._pulse(axis)
        moved = {d: r for d, r in responses.items() if r.direction() != 0}
        # Speeds and echoed commands are exact; a position alone may be noise when
        # another device answers by its speed.
        strong = {d for d, r in moved.items() if r.speed_raw or r.command_raw}
        if strong:
            moved = {d: moved[d] for d in strong}
        joints = [d for d in moved if d in self._joints]
        tracks = [d for d in moved if self._is_track(d)]
        others = [d for d in moved if d not in joints and d not in tracks]
        if not moved:
            self.operator.say(f"axis {axis}: nothing answers")
            return False
        if len(joints) == 1 and not tracks and not others:
            joint = self._identify(joints[0], moved[joints[0]])
            if joint is not None:
                self._map_joint(axis, joint, responses[joints[0]])
            return True
        if len(tracks) == 2 and not joints and not others:
            self._map_drive(axis, {d: moved[d] for d in tracks})
            return True
        log.info("axis %d: ambiguous responses %s", axis, moved)
        names = [self._name(d) for d in moved]
        self._finding(
            MISMATCH,
            f"axis {axis} moves several motors ({', '.join(names)}): not mapped",
        )
        return True

    def _pulse(self, axis: int) -> dict[int, _Response]:
        """Pulse an axis out and back (a third leg if the first direction was blocked);
        what each device did during the first leg."""
        value = self.config.scan_axis_value
        self._allowed = None
        before = self._settle()
        start = self.clock()
        margin = self._margin_s
        try:
            self._command({axis: value})

            def answered() -> bool:
                return any(s.received_at >= start + margin for s in self.log.samples(start))

            self.log.wait(answered, margin + 3 * self._period_s + 1.0, self._poll)
        finally:
            self._zero()
        duration = self.clock() - start
        after = self._settle()
        during = self.log.samples(start)
        first = self._responses(before, after, during)
        self._learn_round_trip(start, during)
        joints = [d for d, r in first.items() if d in self._joints and r.direction()]
        moved_tracks = [d for d, r in first.items() if self._is_track(d) and r.speed_raw]
        if not joints and not moved_tracks:
            return first
        # Back the way it came; a joint that did not move (at a stop) moves away and back.
        back_start = self.clock()
        self._legs(axis, [(-value, duration)])
        after_back = self._settle()
        back = self._responses(after, after_back, self.log.samples(back_start))
        for device_id in joints:
            joint = self._joints[device_id]
            if first[device_id].moved_ticks or first[device_id].speed_raw:
                joint.free.add(first[device_id].direction())
            if back[device_id].moved_ticks or back[device_id].speed_raw:
                joint.free.add(back[device_id].direction())
            speeds = [r.speed_raw for r in (first[device_id], back[device_id]) if r.speed_raw]
            if speeds:
                joint.scan_speed_rad_s = max(abs(s) for s in speeds) / self.speed_scale
                if joint.rough_ticks_per_rad is None:
                    runs = self._runs(joint, self.log.samples(start))
                    try:
                        fit = fit_ticks_per_rad([run for run, _ in runs])
                    except FitError:
                        fit = None
                    # Short noisy runs may tell nothing: only a fit known to 15 % is used.
                    error = fit.relative_error if fit is not None else None
                    if fit is not None and error is not None and error <= ROUGH_FIT_ERROR:
                        joint.rough_ticks_per_rad = abs(fit.value)
            blocked_first = not first[device_id].moved_ticks and not first[device_id].speed_raw
            if blocked_first and (back[device_id].moved_ticks or back[device_id].speed_raw):
                self._legs(axis, [(value, duration)])
                self._settle()
        return first

    def _learn_round_trip(self, start: float, during: Sequence[Sample]) -> None:
        """The round trip from a pulse's first echo; the scan restarts if it was too slow."""
        noise = self.config.speed_noise_raw
        for sample in during:
            if any(
                abs(r.speed_command) > noise or abs(r.speed) > noise for r in sample.motors.values()
            ):
                self._round_trips.append(sample.received_at - start)
                break
        if not self._round_trips:
            return
        margin = max(self.config.min_margin_s, 1.5 * min(self._round_trips) + 0.05)
        if margin > self._margin_s:
            # The pulses so far were judged with too short a wait: a reply may have been
            # counted as the next axis's. Scan again with the longer wait.
            self._margin_s = margin
            raise _RescanError(margin)
        self._margin_s = margin

    def _responses(
        self, before: Sample, after: Sample, during: Iterable[Sample]
    ) -> dict[int, _Response]:
        noise = self.config.speed_noise_raw
        speed: dict[int, int] = {}
        command: dict[int, int] = {}
        for sample in during:
            for device_id, record in sample.motors.items():
                if abs(record.speed) > max(abs(speed.get(device_id, 0)), noise):
                    speed[device_id] = record.speed
                if abs(record.speed_command) > max(abs(command.get(device_id, 0)), noise):
                    command[device_id] = record.speed_command
        responses: dict[int, _Response] = {}
        for device_id in after.motors:
            moved = 0
            joint = self._joints.get(device_id)
            if joint is not None and device_id in before.motors:
                delta = tick_delta(
                    before.motors[device_id].position, after.motors[device_id].position
                )
                # Beyond three times the spread of the resting readings (and a few ticks):
                # a real move, not noise.
                moved = delta if abs(delta) > 3 * joint.noise_ticks + 3 else 0
            responses[device_id] = _Response(
                speed.get(device_id, 0), command.get(device_id, 0), moved
            )
        return responses

    def _is_track(self, device_id: int) -> bool:
        motor = self.profile.motor_by_device(device_id)
        return motor is not None and motor.track is not None

    def _name(self, device_id: int) -> str:
        motor = self.profile.motor_by_device(device_id)
        return f"device {device_id} ({motor.name})" if motor else f"device {device_id}"

    def _identify(self, device_id: int, response: _Response) -> _Joint | None:
        """The joint a device is: the profile's, unless the operator names another."""
        joint = self._joints[device_id]
        profile_motor = self.profile.motor_by_device(device_id)
        choices = [m.name for m in self.profile.motors.values() if m.has_position]
        answer = self.operator.identify_joint(
            device_id, profile_motor.name if profile_motor else None, choices
        )
        if answer is not None and (profile_motor is None or answer != profile_motor.name):
            motor = self.profile.motors[answer]
            self._finding(
                NOTE,
                f"device {device_id} is the {answer} (the operator saw it move), not the "
                f"{profile_motor.name if profile_motor else 'unknown device'} the profile says",
                f"motors.{answer}.device_id",
            )
            self._rename(joint, motor)
            self._measure(
                Measured(
                    f"motors.{answer}.device_id",
                    device_id,
                    f"guided: pulsing one axis moved device {device_id}, and the operator "
                    f"saw the {answer} move",
                )
            )
        elif joint.motor.name.startswith("device"):
            self._finding(
                MISMATCH,
                f"device {device_id} moves, but the profile has no motor with that ID",
                "motors.*.device_id",
            )
            return None
        return joint

    def _rename(self, joint: _Joint, motor: Motor) -> None:
        """The device is another motor than the profile says: its zero offset goes with it."""
        old = joint.motor.name
        if self._zero_owner.get(old) == joint.device_id:
            del self._zero_owner[old]
            del self.result.measured[f"motors.{old}.zero_offset_ticks"]
        # A device the profile gave this name to is not that motor (and is still unknown).
        for other in self._joints.values():
            if other is not joint and other.motor.name == motor.name:
                other.motor = _unknown_motor(other.device_id)
        joint.motor = motor
        self._record_zero(joint)

    def _map_joint(self, axis: int, joint: _Joint, response: _Response) -> None:
        channel = joint.motor.channel
        if channel is None:
            self._finding(
                NOTE, f"axis {axis} moves the {joint.motor.name}, which no channel drives"
            )
            return
        if channel in self._axis_map:
            self._finding(
                MISMATCH,
                f"axis {axis} also moves the {joint.motor.name} (already on axis "
                f"{self._axis_map[channel][0]}): not mapped",
            )
            return
        direction = response.direction()
        if direction == 0 and len(joint.free) == 1:
            # Blocked on the way out, and no echoed command: the way back, reversed.
            direction = -next(iter(joint.free))
        sign = POSITIVE if direction > 0 else NEGATIVE
        joint.channel, joint.axis, joint.sign = channel, axis, sign
        self._axis_map[channel] = (axis, sign)
        evidence = (
            "position"
            if response.moved_ticks
            else "speed"
            if response.speed_raw
            else "speed command"
        )
        self._record_axis(
            channel,
            axis,
            sign,
            f"a pulse of {self.config.scan_axis_value:+d} on axis {axis} moved the "
            f"{joint.motor.name} (device {joint.device_id}) {'up' if sign > 0 else 'down'} "
            f"the position scale ({evidence})",
        )

    def _map_drive(self, axis: int, tracks: dict[int, _Response]) -> None:
        sides: dict[str, int] = {}
        for device_id, response in tracks.items():
            motor = self.profile.motor_by_device(device_id)
            assert motor is not None
            assert motor.track is not None
            sides[motor.track] = response.direction()
        drive = self.profile.drive_channels
        if drive is None or set(sides) != {"left", "right"}:
            self._finding(MISMATCH, f"axis {axis} moves the tracks, but the profile has no drive")
            return
        linear, turn = drive
        if sides["left"] == sides["right"]:
            channel, sign = linear, sides["left"]
            how = "both tracks answered with one sign (drive: linear)"
        else:
            channel, sign = turn, sides["right"]
            how = "the tracks answered with opposite signs (drive: turn; right forward = left)"
        if channel in self._axis_map:
            self._finding(MISMATCH, f"axis {axis} also drives {channel}: not mapped")
            return
        self._axis_map[channel] = (axis, sign)
        self._record_axis(
            channel,
            axis,
            sign,
            f"a pulse of {self.config.scan_axis_value:+d} on axis {axis}: {how}",
        )

    def _record_axis(self, channel: str, axis: int, sign: int, how: str) -> None:
        self.operator.say(f"axis {axis} -> {channel}, sign {sign:+d}")
        self._measure(Measured(f"channels.{channel}.axis", axis, how))
        self._measure(Measured(f"channels.{channel}.axis_sign", sign, how))

    # ---- joint scale and ticks per radian ------------------------------------------------

    def _sweeps(self) -> None:
        for joint in self._joints.values():
            if joint.axis is not None and joint.channel is not None:
                self._sweep(joint)

    def _sweep_plan(self, joint: _Joint) -> tuple[int, list[tuple[int, float]], float]:
        """Axis value, legs of one cycle, and the speed aimed at (rad/s)."""
        config = self.config
        assert joint.axis is not None
        margin = self._margin_s
        symmetric = len(joint.free) != 1
        # A leg long enough for two readings at a constant speed (the middle leg of a
        # symmetric cycle is twice as long as the outer ones).
        need_s = 1.1 * self._period_s * (1 if symmetric else 2) + margin / 2
        budget_rad = math.radians(config.planned_excursion_deg)
        noise_rad = self._noise_rad(joint)
        # Noisy readings need longer runs: the slope of a run of n readings spread over a
        # travel of d is known to about noise·sqrt(12/n)/d; aim at `noisy_run_error` per run,
        # but never slower than `min_sweep_speed_rad_s` (the speed report's resolution).
        # A one-sided cycle runs each way for two legs: it travels twice as far from the start.
        reach = 1.0 if symmetric else 2.0
        noisy_s = 0.0
        if noise_rad > 0.0:
            ratio = noise_rad * math.sqrt(12.0) / (budget_rad * config.noisy_run_error)
            # The noise is reckoned with a rough ticks per radian (the profile's may be 50 %
            # off): whatever it says, noisy runs use the whole budget, the travel that divides
            # the noise; at full speed that costs no more time than shorter cycles repeated.
            full_s = budget_rad / (reach * config.joint_speed_rad_s)
            noisy_s = max(ratio**2 * self._period_s, full_s)
        slowest_s = budget_rad / (reach * config.min_sweep_speed_rad_s)
        leg_s = max(config.min_leg_s, need_s, min(noisy_s, slowest_s))
        speed = min(config.joint_speed_rad_s, budget_rad / (reach * leg_s))
        scan = joint.scan_speed_rad_s or (config.scan_axis_value / self._assumed_scale(joint))
        scale = config.scan_axis_value / scan
        value = max(1, min(AXIS_MAX, round(speed * scale)))
        out = joint.sign * value
        log.info(
            "%s: plan leg %.2f s, speed %.3f rad/s, scan speed %s, free %s, noise %.2f°",
            joint.motor.name,
            leg_s,
            speed,
            joint.scan_speed_rad_s,
            joint.free,
            math.degrees(noise_rad),
        )
        if symmetric:
            legs = [(out, leg_s), (-out, 2 * leg_s), (out, leg_s)]
        else:
            way = next(iter(joint.free))
            legs = [(way * out, 2 * leg_s), (-way * out, 2 * leg_s)]
        return value, legs, value / scale

    def _noise_rad(self, joint: _Joint) -> float:
        """The standard deviation of a resting reading, in radians (rough until measured)."""
        ticks_per_rad = self._rough_ticks(joint)
        if joint.noise_ticks <= 2:
            return 0.0
        # The spread of n uniform readings is about 0.8 of their full range: sigma ~ range/3.5.
        return joint.noise_ticks / 3.0 / abs(ticks_per_rad)

    def _assumed_scale(self, joint: _Joint) -> float:
        assert joint.channel is not None
        return self.profile.channels[joint.channel].axis_per_unit

    def _sweep(self, joint: _Joint) -> None:
        assert joint.axis is not None
        assert joint.channel is not None
        name = joint.motor.name
        value, legs, speed = self._sweep_plan(joint)
        self.operator.say(
            f"{name}: sweeps of ±{value} on axis {joint.axis} (about {math.degrees(speed):.1f}°/s)"
        )
        self._expected_rad_s = speed
        self._allowed = {joint.device_id}
        start_sample = self._settle()
        begin = self.clock()
        k_fit: Fit | None = None
        runs: list[tuple[Run, int]] = []
        try:
            for _ in range(self.config.max_sweep_cycles):
                self._legs(joint.axis, legs)
                self._settle()
                runs = self._runs(joint, self.log.samples(begin))
                try:
                    k_fit = fit_ticks_per_rad([run for run, _ in runs], self.speed_step_rad_s)
                except FitError:
                    k_fit = None
                # Back to the start after every cycle: a lost or late command stretches a
                # leg, and cycles must not add up.
                if k_fit is not None and (k_fit.relative_error or 1.0) <= ROUGH_FIT_ERROR:
                    joint.rough_ticks_per_rad = abs(k_fit.value)
                estimate = self._rough_ticks(joint)
                self._return_to(joint, start_sample, speed, value, estimate)
                good = sum(1 for run, _ in runs if len(run.times_s) >= 2)
                # Only the statistical part: more cycles do not lower the speed's rounding.
                error = k_fit.relative_error if k_fit is not None else None
                if good >= 2 and error is not None and error <= self.config.target_relative_error:
                    break
            if k_fit is None:
                self._finding(
                    MISMATCH,
                    f"{name}: no two readings at a constant speed; ticks per radian not measured",
                    f"motors.{name}.ticks_per_rad",
                )
                return
            ticks_per_rad = k_fit.value
            if ticks_per_rad < 0:
                self._finding(
                    NOTE,
                    f"{name}: the reported speed has the opposite sign of the position's change",
                )
                ticks_per_rad = -ticks_per_rad
            joint.ticks_per_rad = ticks_per_rad
            self._record_sweep(joint, k_fit, ticks_per_rad, runs, value)
        finally:
            self._allowed = None
            self._expected_rad_s = self.config.joint_speed_rad_s

    def _rough_ticks(self, joint: _Joint) -> float:
        """The best ticks per radian known so far: measured, from the scan, or assumed."""
        if joint.ticks_per_rad is not None:
            return joint.ticks_per_rad
        if joint.rough_ticks_per_rad is not None:
            return joint.rough_ticks_per_rad
        return joint.motor.ticks_per_rad or DEFAULT_TICKS_PER_RAD

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

    def _record_sweep(
        self,
        joint: _Joint,
        k_fit: Fit,
        ticks_per_rad: float,
        runs: Sequence[tuple[Run, int]],
        value: int,
    ) -> None:
        assert joint.channel is not None
        name = joint.motor.name
        speeds = [abs(speed_raw) / self.speed_scale for _, speed_raw in runs]
        scale_fit = fit_through_origin(
            speeds, [float(value)] * len(speeds), "axis", x_step=self.speed_step_rad_s
        )
        self._measure(
            Measured(
                f"motors.{name}.ticks_per_rad",
                round(ticks_per_rad, 3),
                f"sweeps about the start pose: positions against the robot's clock in "
                f"{len(runs)} runs at constant reported speed (speed unit "
                f"si.telemetry_speed_per_rad_s = {self.speed_scale:g})",
                residual=round(k_fit.residual, 3),
                residual_unit="ticks",
                samples=k_fit.samples,
            )
        )
        self._measure(
            Measured(
                f"channels.{joint.channel}.axis_per_unit",
                round(scale_fit.value, 3),
                f"axis value {value} against the speed the robot reported in {len(runs)} runs",
                residual=round(scale_fit.residual, 3),
                residual_unit="axis",
                samples=len(runs),
            )
        )
        slowest = min(abs(speed_raw) for _, speed_raw in runs)
        self.operator.say(
            f"{name}: {ticks_per_rad:.1f} ticks/rad {_stated(k_fit)}, "
            f"{scale_fit.value:.0f} axis per rad/s {_stated(scale_fit)} (about 95 %; the "
            f"speed it rests on is reported to 1 part in {slowest})"
        )

    def _return_to(
        self, joint: _Joint, target: Sample, speed_rad_s: float, value: int, ticks_per_rad: float
    ) -> None:
        """Move the joint back to where a sample saw it (sweeps drift with the link's jitter)."""
        assert joint.axis is not None
        away = round(
            statistics.median(
                tick_delta(target.motors[joint.device_id].position, p)
                for p in self._rest_positions(joint)
            )
        )
        away_rad = away / ticks_per_rad
        if abs(away_rad) < math.radians(0.3) + joint.noise_ticks / 3 / ticks_per_rad:
            return
        direction = NEGATIVE if away_rad > 0 else POSITIVE
        self._legs(joint.axis, [(direction * joint.sign * value, abs(away_rad) / speed_rad_s)])
        self._settle()

    def _rest_positions(self, joint: _Joint) -> list[int]:
        """Positions of a settled joint: several readings when they are noisy."""
        wanted = 1 if joint.noise_ticks <= 2 else 5
        since = self.clock()
        samples = self._wait_samples(since, wanted, (wanted + 2) * self._period_s + 1)
        latest = self.log.latest()
        if not samples and latest is not None:
            samples = [latest]
        return [s.motors[joint.device_id].position for s in samples[-wanted:]]

    # ---- guided steps --------------------------------------------------------------------

    def _known_angles(self) -> None:
        """Move each calibrated joint by a known angle; the operator's measurement corrects
        ticks per radian (and the joint scale with it)."""
        for joint in self._joints.values():
            if joint.ticks_per_rad is None or joint.axis is None or joint.channel is None:
                continue
            if self.operator.checks_angle(joint.motor.name):
                self._known_angle(joint)

    def _known_angle(self, joint: _Joint) -> None:
        assert joint.axis is not None
        assert joint.ticks_per_rad is not None
        name = joint.motor.name
        angle_rad = math.radians(
            min(self.config.known_angle_deg, self.config.planned_excursion_deg + 2)
        )
        way = POSITIVE if len(joint.free) != 1 else next(iter(joint.free))
        speed_key = f"channels.{joint.channel}.axis_per_unit"
        scale = self.result.measured[speed_key].value
        value = max(1, round(self.config.joint_speed_rad_s * scale))
        self._allowed = {joint.device_id}
        try:
            before = self._settle()
            self._legs(
                joint.axis, [(way * joint.sign * value, angle_rad / self.config.joint_speed_rad_s)]
            )
            after = self._settle()
            ticks = tick_delta(
                before.motors[joint.device_id].position, after.motors[joint.device_id].position
            )
            reckoned_deg = math.degrees(abs(ticks) / joint.ticks_per_rad)
            measured_deg = self.operator.measured_angle(name, reckoned_deg)
            if measured_deg is not None:
                corrected = abs(ticks) / math.radians(abs(measured_deg))
                ratio = corrected / joint.ticks_per_rad
                self._finding(
                    NOTE if abs(ratio - 1) < 0.03 else MISMATCH,
                    f"{name}: the operator measured {abs(measured_deg):.2f}° where the speed "
                    f"reports say {reckoned_deg:.2f}° ({(ratio - 1) * 100:+.1f} %)"
                    + (
                        ""
                        if abs(ratio - 1) < 0.03
                        else ": si.telemetry_speed_per_rad_s may be wrong"
                    ),
                    "si.telemetry_speed_per_rad_s",
                )
                joint.ticks_per_rad = corrected
                old = self.result.measured[speed_key]
                self._measure(
                    Measured(
                        f"motors.{name}.ticks_per_rad",
                        round(corrected, 3),
                        f"guided: a move of {abs(ticks)} ticks the operator measured as "
                        f"{abs(measured_deg):g}°",
                        samples=1,
                    )
                )
                self._measure(
                    Measured(
                        speed_key,
                        round(old.value * ratio, 3),
                        f"{old.how}, rescaled by the operator's measured angle",
                        residual=old.residual,
                        residual_unit=old.residual_unit,
                        samples=old.samples,
                    )
                )
            self._legs(
                joint.axis, [(-way * joint.sign * value, angle_rad / self.config.joint_speed_rad_s)]
            )
            self._settle()
        finally:
            self._allowed = None

    def _limits(self) -> None:
        """Slow moves to each chosen joint's hard stops; the stop positions become limits."""
        for joint in self._joints.values():
            if joint.ticks_per_rad is None or joint.axis is None:
                continue
            if self.operator.wants_limits(joint.motor.name):
                self._limit(joint)

    def _limit(self, joint: _Joint) -> None:
        assert joint.axis is not None
        assert joint.ticks_per_rad is not None
        assert joint.channel
        name = joint.motor.name
        scale = self.result.measured[f"channels.{joint.channel}.axis_per_unit"].value
        speed = self.config.limit_speed_rad_s
        value = max(1, round(speed * scale))
        stops: dict[int, float] = {}
        self._allowed = {joint.device_id}
        self._expected_rad_s = speed
        self._limit_search = True
        try:
            start = self._settle()
            for way in (NEGATIVE, POSITIVE):
                stops[way] = self._seek_stop(joint, way * joint.sign * value, speed)
            low, high = sorted(stops.values())
            margin = self.config.limit_margin_deg
            limits = [round(low + margin, 2), round(high - margin, 2)]
            self._measure(
                Measured(
                    f"motors.{name}.limits_deg",
                    limits,
                    f"guided: slow moves at {math.degrees(speed):.1f}°/s until the joint "
                    f"stopped at its hard stops ({low:.2f}°, {high:.2f}°), {margin:g}° inside",
                )
            )
            target = start.motors[joint.device_id].position
            latest = self.log.latest()
            assert latest is not None
            away = tick_delta(target, latest.motors[joint.device_id].position) / joint.ticks_per_rad
            direction = NEGATIVE if away > 0 else POSITIVE
            self._legs(joint.axis, [(direction * joint.sign * value, abs(away) / speed)])
            self._settle()
        finally:
            self._limit_search = False
            self._allowed = None
            self._expected_rad_s = self.config.joint_speed_rad_s

    def _seek_stop(self, joint: _Joint, value: int, speed: float) -> float:
        """Move until the joint stops moving (a hard stop); its angle there, in degrees."""
        assert joint.axis is not None
        assert joint.ticks_per_rad is not None
        zero = self.result.measured.get(f"motors.{joint.motor.name}.zero_offset_ticks")
        offset = zero.value if zero is not None else joint.start_ticks
        start = self.clock()
        travel_s = math.radians(self.config.limit_travel_deg) / speed
        try:
            self._command({joint.axis: value})
            while True:
                self._poll()
                samples = self.log.samples(start + self._margin_s)
                still = [
                    s
                    for s in samples[-2:]
                    if abs(s.motors[joint.device_id].speed) <= self.config.speed_noise_raw
                ]
                if len(samples) >= 3 and len(still) == 2:
                    break
                if self.clock() - start > travel_s:
                    raise CalibrationAbortedError(
                        f"the {joint.motor.name} found no hard stop within "
                        f"{self.config.limit_travel_deg:g}°"
                    )
                self.stop.wait(self.config.control_period_s)
        finally:
            self._zero()
        after = self._settle()
        ticks = tick_delta(offset, after.motors[joint.device_id].position)
        return math.degrees(ticks / joint.ticks_per_rad)

    def _drive_constants(self) -> None:
        for kind in (LINEAR, ROTATION):
            plan = self.operator.drive_plan(kind)
            if plan is not None:
                self._drive_runs(plan)

    def _drive_runs(self, plan: DrivePlan) -> None:
        """Seed 000 §3.1: constant axis values, distance over time, least squares."""
        drive = self.profile.drive_channels
        if drive is None:
            return
        channel = drive[0] if plan.kind == LINEAR else drive[1]
        if channel not in self._axis_map:
            self._finding(MISMATCH, f"{plan.kind} drive constant: {channel} has no axis")
            return
        axis, sign = self._axis_map[channel]
        assumed = self.profile.channels[channel].axis_per_unit
        values: list[float] = []
        speeds: list[float] = []
        durations: list[float] = []
        tracks = {m.device_id for m in self.profile.motors.values() if m.track is not None}
        self._allowed = tracks
        self._expected_rad_s = max(plan.speeds) * 2
        try:
            for index, speed in enumerate(plan.speeds):
                value = round(speed * assumed)
                self._settle()
                commanded = self._drive_run(axis, sign * value, plan, index)
                durations.append(commanded)
                typed = self.operator.drive_time(plan.kind, index, commanded)
                if typed is None or typed <= 0:
                    continue
                values.append(float(value))
                speeds.append(plan.distance / typed)
        finally:
            self._allowed = None
            self._expected_rad_s = self.config.joint_speed_rad_s
        if not speeds:
            return
        fit = fit_through_origin(speeds, values, "axis")
        key = "si.linear_axis_per_m_s" if plan.kind == LINEAR else "si.rotation_axis_per_rad_s"
        unit = "m" if plan.kind == LINEAR else "rad"
        self._measure(
            Measured(
                key,
                round(fit.value, 3),
                f"guided, seed 000 §3.1: {len(speeds)} run(s) of {plan.distance:g} {unit} at "
                f"axis values {[int(v) for v in values]}, timed by the operator; least squares",
                residual=round(fit.residual, 3),
                residual_unit="axis",
                samples=len(speeds),
            )
        )

    def _drive_run(self, axis: int, value: int, plan: DrivePlan, index: int) -> float:
        """One run: until the given time, or until the operator lets go of the deadman."""
        start = self.clock()
        stop_after = plan.stop_after_s[index] if plan.stop_after_s is not None else None
        try:
            self._command({axis: value})
            while stop_after is None or self.clock() - start < stop_after:
                try:
                    self._poll()
                except DeadmanReleasedError:
                    break
                self.stop.wait(self.config.control_period_s)
        finally:
            self._zero()
        return self.clock() - start


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
