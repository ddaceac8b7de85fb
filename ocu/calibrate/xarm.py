"""`ocu calibrate` on an xArm 1S: each joint's zero offset and direction (docs/calibration.md,
"An xArm 1S").

Four steps over the xArm link (`XarmLink`, given a raw copy of the profile: sign 1, offset 0,
so that a goal in radians is a servo position): (1) listen: every servo's position and the
battery are read, a servo that does not answer is named and the calibration refused; (2) the
operator puts the arm in its zero pose and confirms: offset = reading - 500 per joint,
refused when further from 500 than `MAX_OFFSET_UNITS`; (3) each joint makes one small slow
move from the zero pose (within its limits, only while the deadman is held; a stop sends the
stop move of every servo), the operator says whether it went the way docs/xarm.md names as
positive (the sign is flipped if not), and it moves back; (4) the profile is written: the
base file's text with the new `sign` and `offset` lines, every other line and comment kept.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import math
import re
import statistics
import threading
import time
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from ocu.calibrate.guard import CalibrationAbortedError, Deadman, StopSignal
from ocu.files import write_text_atomically
from ocu.link.xarm import XarmLink
from ocu.link.xarm_wire import XarmStatus, XarmTelemetry
from ocu.profile.keys import ProfileError
from ocu.profile.xarm import CENTRE_UNITS, XarmJoint, XarmProfile, parse_xarm_profile
from ocu.records import Command, LinkEvent, SafetyEvent, StatusFrame, TelemetryFrame

#: What each joint's positive direction is (docs/xarm.md "The URDF and the IK"; the wrist
#: roll's and the gripper's are this project's convention).
POSITIVE = {
    "base": "turn left (counter-clockwise seen from above)",
    "shoulder": "tilt forward",
    "elbow": "tilt forward",
    "wrist_pitch": "tilt forward",
    "wrist_roll": "turn counter-clockwise seen from the gripper's end",
    "gripper": "close",
}
#: The zero pose (docs/xarm.md): what the operator is asked to set up.
ZERO_POSE = (
    "the arm standing upright (shoulder, elbow and wrist in one vertical line), the base "
    "facing forward, the gripper's jaws opening to the arm's left and right, the gripper half "
    "open"
)
#: A zero reading further than this from 500 (36°) is not a mounting error but a pose.
MAX_OFFSET_UNITS = 150
#: The direction move: this far (degrees) in this long (a slow move: 5°/s).
PROBE_DEG = 5.0
PROBE_S = 1.0
#: How long the listening step waits for every servo and the battery.
LISTEN_S = 3.0
#: How long a move may take to be read at its end after its time.
SETTLE_S = 3.0
#: A move's end is read within this of its target (units); the joint moved if by half.
ARRIVED_UNITS = 3
POLL_S = 0.02
#: Readings of the zero pose whose median is taken.
ZERO_READINGS = 5


class XarmOperator(Protocol):
    """Who answers the xArm's calibration (ocu.calibrate.operator's operators do)."""

    def say(self, text: str) -> None:
        """Show what is happening."""
        ...

    def zero_pose_ready(self, text: str) -> bool:
        """Is the arm in its zero pose (False ends the calibration)?"""
        ...

    def moved_positive(self, joint: str, positive: str) -> bool:
        """Did the joint move the positive way? CalibrationAbortedError for "stop"."""
        ...


@dataclass
class XarmCalibrationResult:
    """What the calibration found (servo units), and why it stopped if it did."""

    positions: dict[int, int] = field(default_factory=dict)
    battery_mv: int | None = None
    zero: dict[str, int] = field(default_factory=dict)
    offsets: dict[str, int] = field(default_factory=dict)
    signs: dict[str, int] = field(default_factory=dict)
    aborted: str | None = None
    started_at: dt.datetime = field(default_factory=lambda: dt.datetime.now(dt.UTC))


def raw_arm(arm: XarmProfile) -> XarmProfile:
    """The profile with every joint at sign 1, offset 0: an angle is a servo position."""
    joints = tuple(dataclasses.replace(j, sign=1, offset_units=0) for j in arm.joints)
    return dataclasses.replace(arm, joints=joints)


class _Readings:
    """The link's replies as they come (any thread)."""

    def __init__(self) -> None:
        self.changed = threading.Condition()
        self.positions: dict[int, tuple[int, float]] = {}  # servo -> (units, when)
        self.battery_mv: int | None = None
        self.replies = 0
        self.safety: list[str] = []  # the link's safety events (its watchdogs' stops)

    def __call__(self, event: LinkEvent) -> None:
        if isinstance(event, TelemetryFrame) and isinstance(event.packet, XarmTelemetry):
            with self.changed:
                for motor in event.packet.motors:
                    self.positions[motor.device_id] = (motor.position, event.received_at)
                self.replies += 1
                self.changed.notify_all()
        elif isinstance(event, SafetyEvent):
            with self.changed:
                self.safety.append(event.message)
        elif isinstance(event, StatusFrame) and isinstance(event.packet, XarmStatus):
            with self.changed:
                self.battery_mv = event.packet.voltage_mv
                self.changed.notify_all()


class XarmCalibrator:
    """Runs the four steps over a link made with `link_for` (ocu.calibrate.cli)."""

    def __init__(
        self,
        link: XarmLink,
        arm: XarmProfile,
        operator: XarmOperator,
        *,
        deadman: Deadman,
        stop: StopSignal,
        listen_s: float = LISTEN_S,
        probe_deg: float = PROBE_DEG,
        probe_s: float = PROBE_S,
    ) -> None:
        self.link = link
        self.arm = arm
        self.operator = operator
        self.deadman = deadman
        self.stop = stop
        self.listen_s = listen_s
        self.probe_units = round(probe_deg / 180.0 * math.pi * arm.units_per_rad)
        self.probe_s = probe_s
        self.readings = _Readings()
        link.subscribe(self.readings)

    def run(self) -> XarmCalibrationResult:
        """The calibration; the link is started here and left for the caller to shut down."""
        result = XarmCalibrationResult()
        try:
            self.link.start()
            self._listen(result)
            self._zero(result)
            for joint in self.arm.joints:
                self._direction(joint, result)
        except CalibrationAbortedError as err:
            self.link.emergency_stop(str(err))
            result.aborted = str(err)
        return result

    # ---- step 1: listen -------------------------------------------------------------------

    def _listen(self, result: XarmCalibrationResult) -> None:
        self.operator.say(f"Listening to the board for up to {self.listen_s:g} s ...")
        wanted = {joint.servo for joint in self.arm.joints}
        deadline = time.monotonic() + self.listen_s
        with self.readings.changed:
            while not (
                wanted <= self.readings.positions.keys() and self.readings.battery_mv is not None
            ):
                left = deadline - time.monotonic()
                if left <= 0 or self.stop.stopped:
                    break
                self.readings.changed.wait(min(left, POLL_S))
            positions = {s: p for s, (p, _) in self.readings.positions.items()}
            result.battery_mv = self.readings.battery_mv
            replies = self.readings.replies
        self._check_stop()
        result.positions = positions
        for joint in self.arm.joints:
            if joint.servo in positions:
                self.operator.say(f"{joint.name} (servo {joint.servo}): {positions[joint.servo]}")
        battery = "no answer" if result.battery_mv is None else f"{result.battery_mv} mV"
        self.operator.say(f"battery: {battery}")
        silent = [j for j in self.arm.joints if j.servo not in positions]
        if silent:
            names = ", ".join(f"servo {j.servo} ({j.name})" for j in silent)
            why = (
                f"no reply at all: is it the board, at {self.arm.baud} baud?"
                if replies == 0
                else f"absent from {replies} replies"
            )
            raise CalibrationAbortedError(
                f"{names} did not answer in {self.listen_s:g} s ({why}): check its cable and ID"
            )

    # ---- step 2: zero offsets -------------------------------------------------------------

    def _zero(self, result: XarmCalibrationResult) -> None:
        if not self.operator.zero_pose_ready(f"Put the arm in its zero pose: {ZERO_POSE}."):
            raise CalibrationAbortedError("the arm was not put in its zero pose")
        self._check_stop()
        # The median of a few readings: one noisy reading would be the offset for good.
        samples = [self._fresh_positions() for _ in range(ZERO_READINGS)]
        positions = {
            servo: round(statistics.median(sample[servo] for sample in samples))
            for servo in samples[0]
        }
        problems = []
        for joint in self.arm.joints:
            raw = positions[joint.servo]
            offset = raw - CENTRE_UNITS
            degrees = math.degrees(offset / self.arm.units_per_rad)
            if abs(offset) > MAX_OFFSET_UNITS:
                problems.append(
                    f"the {joint.name} reads {raw} in the zero pose, {offset:+d} units "
                    f"({degrees:+.0f}°) from 500, more than {MAX_OFFSET_UNITS}: not in its zero "
                    "pose, or its horn is a spline off (remount it)"
                )
            elif not joint.min_units <= raw <= joint.max_units:
                problems.append(
                    f"the {joint.name} reads {raw}, outside its limits "
                    f"{joint.min_units}-{joint.max_units}"
                )
            result.zero[joint.name] = raw
            result.offsets[joint.name] = offset
            self.operator.say(f"{joint.name}: zero at {raw}, offset {offset:+d} ({degrees:+.1f}°)")
        if problems:
            raise CalibrationAbortedError("; ".join(problems))

    def _fresh_positions(self) -> dict[int, int]:
        """Every servo's position read after now."""
        since = time.monotonic()
        deadline = since + self.listen_s
        wanted = {joint.servo for joint in self.arm.joints}
        with self.readings.changed:
            while True:
                fresh = {s: p for s, (p, at) in self.readings.positions.items() if at > since}
                if wanted <= fresh.keys():
                    return fresh
                left = deadline - time.monotonic()
                if left <= 0:
                    missing = sorted(wanted - fresh.keys())
                    raise CalibrationAbortedError(f"servo(s) {missing} stopped answering")
                self.readings.changed.wait(min(left, POLL_S))
                self._check_stop()

    # ---- step 3: directions ---------------------------------------------------------------

    def _direction(self, joint: XarmJoint, result: XarmCalibrationResult) -> None:
        zero = result.zero[joint.name]
        # The profile's positive way, or the other if the limits leave no room for it.
        step = joint.sign * self.probe_units
        if not joint.min_units <= zero + step <= joint.max_units:
            step = -step
        if not joint.min_units <= zero + step <= joint.max_units:
            raise CalibrationAbortedError(
                f"the {joint.name}'s limits leave no room for a {self.probe_units}-unit move"
            )
        commanded_positive = step * joint.sign > 0
        way = POSITIVE.get(joint.name, "move the positive way")
        self.operator.say(
            f"Moving the {joint.name} by {abs(step)} units "
            f"({math.degrees(abs(step) / self.arm.units_per_rad):.1f}°) in {self.probe_s:g} s."
        )
        reached = self._move(joint, zero + step)
        if abs(reached - zero) < abs(step) / 2:
            raise CalibrationAbortedError(
                f"the {joint.name} did not move: read {reached} after a move from {zero} to "
                f"{zero + step}"
            )
        positive = self.operator.moved_positive(joint.name, way)
        sign = joint.sign if positive == commanded_positive else -joint.sign
        result.signs[joint.name] = sign
        self.operator.say(
            f"{joint.name}: sign {sign:+d}" + (" (flipped)" if sign != joint.sign else "")
        )
        self._move(joint, zero)

    def _move(self, joint: XarmJoint, target: int) -> int:
        """One timed move of the joint to `target` (units) while the deadman is held; where
        it was read at the end. A stop: CalibrationAbortedError (the caller stops every
        servo); the deadman let go: the stop move, and the move again once it is held."""
        goal = (target - CENTRE_UNITS) / self.arm.units_per_rad  # raw link: an angle is a unit
        while True:
            self._wait_for_deadman(joint)
            here = self.link.setpoints().get(joint.servo, float(target))
            with self.readings.changed:
                safety_seen = len(self.readings.safety)
            end = time.monotonic() + self.probe_s
            # The goal's velocity is the move's mean speed (a goal is a motion command).
            speed = (target - here) / self.arm.units_per_rad / self.probe_s
            self.link.heartbeat()
            if speed != 0.0:
                self.link.set_command(
                    Command(
                        velocities={joint.name: speed},
                        goals={joint.name: goal},
                        until={joint.name: end},
                    )
                )
            deadline = end + SETTLE_S
            while True:
                self._check_stop()
                self.link.heartbeat()
                if not self.deadman.held():
                    self.link.emergency_stop("deadman released")
                    self.operator.say(f"deadman released: the {joint.name} stopped")
                    break
                now = time.monotonic()
                raw = self._position_after(joint.servo, now)
                # The link's move ends up to 1 ms after `end` (whole milliseconds): clearing
                # the command before it ended would send a stop move of this joint.
                if now >= end + POLL_S and raw is not None and abs(raw - target) <= ARRIVED_UNITS:
                    self.link.set_command(Command())
                    return raw
                if now > deadline:
                    self.link.emergency_stop("move not completed")
                    with self.readings.changed:
                        why = "; ".join(self.readings.safety[safety_seen:])
                    raise CalibrationAbortedError(
                        f"the {joint.name} did not reach {target} within "
                        f"{self.probe_s + SETTLE_S:g} s (read {raw})"
                        + (f": the link stopped it ({why})" if why else "")
                    )
                self.stop.wait(POLL_S)

    def _position_after(self, servo: int, since: float) -> int | None:
        with self.readings.changed:
            position, at = self.readings.positions.get(servo, (None, -math.inf))
        return position if at > since - POLL_S * 5 else None

    def _wait_for_deadman(self, joint: XarmJoint) -> None:
        said = False
        while not self.deadman.held():
            if not said:
                self.operator.say(f"Hold the deadman to move the {joint.name}.")
                said = True
            self._check_stop()
            self.stop.wait(POLL_S)
        self._check_stop()

    def _check_stop(self) -> None:
        if self.stop.stopped:
            raise CalibrationAbortedError(self.stop.reason)


# ---- step 4: the profile ------------------------------------------------------------------

_JOINTS_HEADER = re.compile(r"^\s*\[\[\s*joints\s*\]\]\s*(#.*)?$")
_TABLE_HEADER = re.compile(r"^\s*\[")
HEADER_START = "# xArm profile written by `ocu calibrate`"
_NAME = re.compile(r'^\s*name\s*=\s*"([^"]*)"')
_KEY = re.compile(r"^(\s*)(sign|offset)(\s*=\s*)([^#\s]+)(\s*#.*)?$")


def calibrated_xarm_text(
    base_text: str, result: XarmCalibrationResult, *, robot: str, base_name: str
) -> str:
    """The base profile's text with the measured `sign` and `offset` lines (each with a
    comment saying how it was measured); every other line kept as it is."""
    stamp = result.started_at.replace(microsecond=0).isoformat()
    lines = [
        f"{HEADER_START} for {robot} on {stamp} from {base_name}:",
        "# each joint's `sign` and `offset` were measured (docs/calibration.md, An xArm 1S).",
    ]
    joint: str | None = None
    base_lines = base_text.splitlines()
    if base_lines[:1] and base_lines[0].startswith(HEADER_START):
        base_lines = base_lines[2:]  # a calibrated profile calibrated again: one header
    for original in base_lines:
        line = original
        if _JOINTS_HEADER.match(line):
            joint = ""
        elif _TABLE_HEADER.match(line):
            joint = None
        elif joint == "" and (name := _NAME.match(line)):
            joint = name.group(1)
        elif joint and (key := _KEY.match(line)):
            indent, what, equals = key.group(1), key.group(2), key.group(3)
            if what == "offset" and joint in result.offsets:
                how = f"# measured: read {result.zero[joint]} in the zero pose"
                line = f"{indent}offset{equals}{result.offsets[joint]}  {how}"
            elif what == "sign" and joint in result.signs:
                line = f"{indent}sign{equals}{result.signs[joint]}  # measured: a 5° move seen"
        lines.append(line)
    return "\n".join(lines) + "\n"


def check_out_file(path: Path) -> None:
    """ProfileError if `path` exists and cannot be read as TOML: it is not overwritten."""
    if not path.exists():
        return
    try:
        tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise ProfileError(
            f"{path} exists and cannot be read ({err.strerror}): not overwritten"
        ) from err
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise ProfileError(
            f"{path} exists and is not a TOML file ({err}): not overwritten"
        ) from err


def write_xarm_profile(
    path: Path, arm: XarmProfile, result: XarmCalibrationResult, *, robot: str
) -> XarmProfile:
    """Write the calibrated profile atomically if it loads; the profile it holds."""
    check_out_file(path)
    base_text = Path(arm.source).read_text(encoding="utf-8")
    text = calibrated_xarm_text(base_text, result, robot=robot, base_name=arm.source)
    written = parse_xarm_profile(tomllib.loads(text), source=str(path))
    wrong = [
        j.name
        for j in written.joints
        if j.offset_units != result.offsets.get(j.name, j.offset_units)
        or j.sign != result.signs.get(j.name, j.sign)
    ]
    if wrong:
        raise ProfileError(f"{arm.source}: no sign/offset line found for {wrong}")
    write_text_atomically(path, text)
    return written


def summary(result: XarmCalibrationResult, arm: XarmProfile) -> Mapping[str, str]:
    """Joint -> what changed, for the report."""
    lines = {}
    for joint in arm.joints:
        if joint.name in result.offsets:
            sign = result.signs.get(joint.name, joint.sign)
            lines[joint.name] = (
                f"offset {joint.offset_units:+d} -> {result.offsets[joint.name]:+d}, "
                f"sign {joint.sign:+d} -> {sign:+d}"
            )
    return lines
