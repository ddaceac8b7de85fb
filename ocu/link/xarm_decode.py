"""The board's replies into records: for the live xArm link, its replay and `ocu inspect`.

`XarmDecoder` takes the bytes read from the serial line through the resynchronising frame
reader (ocu.protocol.xarm.FrameReader) and gives the replies it found: the servos' positions
(`PositionsReply`) and the battery (`BatteryReply`). Its `tap` is handed every whole frame as a
DatagramReceived of kind XARM_FROM_BOARD and every run of skipped bytes as OTHER, so a
recording holds exactly what the reader saw. `readings` turns a position reply into the
joints' readings as the link reports them: the angle (None, with a fault, for a position no
servo can have), the speed from the last two believable readings, and the setpoint's end
(the link's copy of where the board moves the servo) as the target.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from ocu.link.xarm_wire import Ramp, XarmMotor
from ocu.profile.xarm import XarmProfile
from ocu.protocol.xarm import (
    Cmd,
    Direction,
    FrameReader,
    XarmProtocolError,
    decode_battery,
    decode_positions,
)
from ocu.records import OTHER, XARM_FROM_BOARD, Command, DatagramReceived, JointReading, Listener

log = logging.getLogger("ocu.link.xarm")

#: Readings outside this window (servo units) are impossible: not believed.
PLAUSIBLE_UNITS = (-100, 1100)


@dataclass(frozen=True)
class PositionsReply:
    """A CMD_MULT_SERVO_POS_READ reply: servo id -> position (servo units)."""

    positions: dict[int, int]


@dataclass(frozen=True)
class BatteryReply:
    """A CMD_GET_BATTERY_VOLTAGE reply."""

    millivolts: int


Reply = PositionsReply | BatteryReply


def plausible(raw: int) -> bool:
    """Whether a servo can report this position."""
    return PLAUSIBLE_UNITS[0] <= raw <= PLAUSIBLE_UNITS[1]


class XarmDecoder:
    """The board's bytes into replies, and position replies into readings (module docstring)."""

    def __init__(
        self,
        arm: XarmProfile,
        *,
        tap: Listener | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.arm = arm
        self.tap = tap
        self.clock = clock
        self.reader = FrameReader(Direction.FROM_BOARD, keep_skipped=tap is not None)
        self.undecodable = 0  # frames of the right shape whose fields made no sense
        self._last_units: dict[int, tuple[float, float]] = {}  # servo -> (units, at)

    @property
    def bad_frames(self) -> int:
        """Episodes of bytes the frame reader could not make a frame of."""
        return self.reader.bad_frames

    def feed(self, data: bytes) -> list[Reply]:
        """The replies complete in these bytes (and those held from before)."""
        frames = self.reader.feed(data)
        now = self.clock()
        tap = self.tap
        if tap is not None:
            # In the order the bytes came: each run of garbage before the frame it preceded.
            runs = self.reader.take_skipped()
            for index, frame in enumerate(frames):
                for _, run in (r for r in runs if r[0] == index):
                    tap(DatagramReceived(run, now, OTHER))
                tap(DatagramReceived(frame.encode(), now, XARM_FROM_BOARD))
            for _, run in (r for r in runs if r[0] == len(frames)):
                tap(DatagramReceived(run, now, OTHER))
        replies: list[Reply] = []
        for frame in frames:
            try:
                if frame.command == Cmd.MULT_SERVO_POS_READ:
                    replies.append(PositionsReply(decode_positions(frame.parameters)))
                elif frame.command == Cmd.GET_BATTERY_VOLTAGE:
                    replies.append(BatteryReply(decode_battery(frame.parameters)))
            except XarmProtocolError as err:
                self.undecodable += 1
                log.debug("reply dropped: %s", err)
        return replies

    def readings(
        self,
        positions: Mapping[int, int],
        now: float,
        setpoints: Mapping[int, Ramp],
        command: Command,
    ) -> tuple[dict[str, JointReading], tuple[XarmMotor, ...]]:
        """The joints' readings of one position reply received at `now`, and the servos'."""
        readings: dict[str, JointReading] = {}
        motors = []
        for joint in self.arm.joints:
            raw = positions.get(joint.servo)
            if raw is None:
                continue
            motors.append(XarmMotor(device_id=joint.servo, position=raw))
            fault = None
            speed = 0.0
            if not plausible(raw):
                fault = f"servo {joint.servo} reported {raw}, outside its range"
            else:
                previous = self._last_units.get(joint.servo)
                if previous is not None and now > previous[1]:
                    speed = (raw - previous[0]) / (now - previous[1])
                self._last_units[joint.servo] = (raw, now)
            ramp = setpoints.get(joint.servo)
            readings[joint.name] = JointReading(
                name=joint.name,
                device_id=joint.servo,
                state=0,
                mode=0,
                angle_rad=None if fault else self.arm.angle_rad(joint, raw),
                speed_rad_s=joint.sign * speed / self.arm.units_per_rad,
                current_a=0.0,
                status=0,
                target_angle_rad=None if ramp is None else self.arm.angle_rad(joint, ramp.end),
                speed_command_rad_s=command.velocity(joint.name),
                current_command_a=0.0,
                fault=fault,
            )
        return readings, tuple(motors)
