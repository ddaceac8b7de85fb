"""An xArm recording played back: the board's frames through the xArm link's own decoder.

`XarmReplayLink` is the ReplayLink of a recording made on an xArm 1S (its attached profile is
an xArm's; `open_replay` in ocu.record.ur_replay picks it). The frames the board sent
(/raw/xarm/from_board) and the bytes the live reader skipped (/raw/other) go through
`XarmDecoder` (ocu.link.xarm_decode), the decoder of the live `XarmLink`, in the order they came,
and come out as the live link emitted them: a `TelemetryFrame` per position reply (its
readings' speeds from the recorded times, their targets from the setpoints the recorded moves
gave, as the link kept them), a `StatusFrame` per battery reply. Each CMD_SERVO_MOVE the OCU
wrote (/raw/xarm/to_board) moves those setpoints and is emitted as the `CommandSent` it
carried: each servo's velocity from its setpoint to the move's target over the move's time
(0 for a stop move). Link states, statistics and safety events come from their channels, as
for the Engineer. Read-only: nothing is sent.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from ocu.link.xarm_decode import BatteryReply, XarmDecoder, plausible
from ocu.link.xarm_moves import XarmMoves
from ocu.link.xarm_wire import Ramp, XarmStatus, XarmTelemetry
from ocu.profile.xarm import XarmProfile
from ocu.protocol.xarm import (
    Cmd,
    Direction,
    FrameReader,
    XarmProtocolError,
    decode_servo_move,
)
from ocu.record import schemas as s
from ocu.record.reader import RecordedMessage
from ocu.record.replay_link import ReplayLink
from ocu.records import Command, StatusFrame, TelemetryFrame


class XarmReplayLink(ReplayLink):
    """An xArm's recording as a read-only Link (see the module docstring)."""

    replayed_topics = frozenset((*s.RAW_XARM_TOPICS, s.RAW_OTHER, s.LINK_STATS, s.EVENTS))
    command_topic = s.RAW_XARM_TO_BOARD

    def __init__(
        self,
        path: str | Path,
        arm: XarmProfile,
        *,
        clock: Callable[[], float] = time.monotonic,
        on_finished: Callable[[], None] | None = None,
    ) -> None:
        self.arm = arm
        self._reset_xarm()
        super().__init__(path, None, clock=clock, on_finished=on_finished)

    def _reset_xarm(self) -> None:
        self.decoder = XarmDecoder(self.arm, clock=self.recorded_now)
        self.moves = XarmMoves(self.arm)
        self._velocities: dict[str, float] = {}
        self._replies = 0
        self._at = 0.0  # the recorded time of the message being replayed (s)

    def recorded_now(self) -> float:
        """The recorded time of the message being decoded (the decoder's clock: the live
        link's decoder read its clock on arrival, which the log time is)."""
        return self._at

    def _reset_decoding(self) -> None:
        super()._reset_decoding()
        self._reset_xarm()

    def _sent(self, message: RecordedMessage, data: bytes, now: float) -> Command | None:
        at = message.log_time_ns / 1e9
        reader = FrameReader(Direction.TO_BOARD)
        changed = False
        for frame in reader.feed(data):
            if frame.command != Cmd.SERVO_MOVE:
                continue
            try:
                move = decode_servo_move(frame.parameters)
            except XarmProtocolError:
                continue
            duration_s = move.duration_ms / 1000.0
            for servo, target in move.positions:
                joint = next((j for j in self.arm.joints if j.servo == servo), None)
                if joint is None:
                    continue
                ramp = self.moves.ramps.get(servo)
                here = float(target) if ramp is None else ramp.value(at)
                speed = (target - here) / duration_s if duration_s > 0.0 else 0.0
                self._velocities[joint.name] = joint.sign * speed / self.arm.units_per_rad
                self.moves.ramps[servo] = Ramp(here, target, at, duration_s)
                changed = True
        if not changed:
            return None
        return Command(velocities=dict(self._velocities))

    def _received(self, message: RecordedMessage, data: bytes) -> None:
        self._at = at = message.log_time_ns / 1e9
        for reply in self.decoder.feed(data):
            self._replies += 1
            if isinstance(reply, BatteryReply):
                status = XarmStatus(voltage_mv=reply.millivolts)
                self.emit(StatusFrame(status, self.clock(), at))
                continue
            for joint in self.arm.joints:
                raw = reply.positions.get(joint.servo)
                if raw is not None and plausible(raw):
                    self.moves.first_reading(joint.servo, raw, at)
            readings, motors = self.decoder.readings(
                reply.positions, at, self.moves.targets(), self.command
            )
            packet = XarmTelemetry(tick=self._replies, motors=motors)
            self.emit(TelemetryFrame(packet, readings, self.clock(), at))
