"""A UR recording played back: the raw packets through the UR link's own decoding.

`open_replay(path)` gives the ReplayLink a recording needs: the Engineer's (datagrams through
ocu.link.receiver) or, for a recording of a Universal Robots arm (its attached profile is a
UR's), `UrReplayLink`: the recorded realtime, secondary and primary packets go through
`UrDecoder` (ocu.link.ur_wire), the decoder of the live `UrLink`, and come out as the live link
emitted them: a `TelemetryFrame` of the newest realtime state at most at the profile's
telemetry rate (with the round trip `SpeedEcho` measures from the recorded speedj lines and
the controller's reaction), a `RobotModeReport` when the controller's mode changes, and for
each recorded speedj the `CommandSent` it carried. Link states, statistics and safety events
come from the channels that recorded them, as for the Engineer. Read-only: nothing is sent.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path

from ocu.link.ur_wire import SpeedEcho, UrDecoder, UrRobotStatus, telemetry_frame
from ocu.profile import RobotProfile
from ocu.profile.ur import UrArmProfile
from ocu.profile.ur_robot import UR_TICKS_PER_RAD
from ocu.protocol.ur import (
    UrProtocolError,
    VersionMessage,
    decode_primary,
    parse_script_line,
    realtime_size,
)
from ocu.protocol.ur.realtime import RealtimeState
from ocu.record import schemas as s
from ocu.record.errors import RecordingError
from ocu.record.reader import RecordedMessage, Recording
from ocu.record.replay_link import ReplayLink
from ocu.records import Command


def open_replay(
    path: str | Path,
    profile: RobotProfile | None = None,
    *,
    clock: Callable[[], float] = time.monotonic,
    on_finished: Callable[[], None] | None = None,
) -> ReplayLink:
    """The replay of a recording, for the robot it was made with (an Engineer, a UR, an
    xArm: ocu.record.xarm_replay); RecordingError, LinkError."""
    with Recording(path) as recording:
        arm = recording.ur_arm()
        xarm = recording.xarm()
    if arm is not None:
        return UrReplayLink(path, arm, clock=clock, on_finished=on_finished)
    if xarm is not None:
        from ocu.record.xarm_replay import XarmReplayLink

        return XarmReplayLink(path, xarm, clock=clock, on_finished=on_finished)
    return ReplayLink(path, profile, clock=clock, on_finished=on_finished)


def script_command(line: bytes, joint_names: tuple[str, ...]) -> Command | None:
    """The command a URScript line the UR link sent carried: speedj's joint speeds; stopj,
    which the link sends for an e-stop or a stop, carries none (None), nor does anything
    that does not parse."""
    try:
        command = parse_script_line(line.decode("ascii"))
    except (UnicodeDecodeError, UrProtocolError):
        return None
    if command.name != "speedj" or command.qd is None:
        return None
    return Command(velocities=dict(zip(joint_names, command.qd, strict=True)))


class UrReplayLink(ReplayLink):
    """A UR arm's recording as a read-only Link (see the module docstring)."""

    replayed_topics = frozenset((*s.RAW_UR_TOPICS, s.LINK_STATS, s.EVENTS))
    command_topic = s.RAW_UR_SCRIPT

    def __init__(
        self,
        path: str | Path,
        arm: UrArmProfile,
        *,
        clock: Callable[[], float] = time.monotonic,
        on_finished: Callable[[], None] | None = None,
    ) -> None:
        self.arm = arm
        # The layout the controller's version message fixed (None: any known one, for a
        # recording started after it).
        self._realtime_size: int | None = None
        self._reset_ur()
        super().__init__(path, None, clock=clock, on_finished=on_finished)

    def _reset_ur(self) -> None:
        self.decoder = UrDecoder(self._realtime_size)
        self._status: UrRobotStatus | None = None
        self._emitted_at = -math.inf
        self._echo = SpeedEcho()
        # The newest state the telemetry rate held back, emitted at the end of the file: the
        # live link would have sent it with the next packet, a file has none.
        self._held: tuple[RealtimeState, float] | None = None

    def _reset_decoding(self) -> None:
        super()._reset_decoding()
        self._reset_ur()

    def _sent(self, message: RecordedMessage, data: bytes, now: float) -> Command | None:
        command = script_command(data, self.arm.joint_names)
        qd = (
            [0.0] * len(self.arm.joint_names)
            if command is None
            else [command.velocity(name) for name in self.arm.joint_names]
        )
        # On the recording's clock, as the live link measured it.
        self._echo.sent(qd, message.log_time_ns / 1e9)
        return command

    def _received(self, message: RecordedMessage, data: bytes) -> None:
        if message.topic == s.RAW_UR_REALTIME:
            self._realtime(message, data)
        elif message.topic == s.RAW_UR_SECONDARY:
            for status in self.decoder.secondary(data):
                if status != self._status:
                    self._status = status
                    self.emit(status.report())
        elif message.topic == s.RAW_UR_PRIMARY:
            self._primary(data)

    def _primary(self, data: bytes) -> None:
        try:
            decoded = decode_primary(data)
        except UrProtocolError:
            return
        if isinstance(decoded, VersionMessage):
            try:
                size = realtime_size(decoded.version)
            except UrProtocolError:
                return
            if size != self._realtime_size:
                self._realtime_size = size
                self.decoder = UrDecoder(size)

    def _realtime(self, message: RecordedMessage, data: bytes) -> None:
        states = self.decoder.realtime(data)
        if not states:
            return
        recorded_at = message.log_time_ns / 1e9
        for state in states:
            self._echo.received(state.qd_target, recorded_at)
        now = self.clock()
        # The live link's rule: the newest state at most at the telemetry rate.
        if now - self._emitted_at < 1.0 / self.profile.link.telemetry_rate_hz:
            self._held = (states[-1], recorded_at)
            return
        self._emit_state(states[-1], recorded_at, now)

    def _emit_state(self, state: RealtimeState, recorded_at: float, now: float) -> None:
        self._emitted_at = now
        self._held = None
        self.emit(
            telemetry_frame(
                state,
                self.arm.joint_names,
                ticks_per_s=self.arm.realtime_hz,
                ticks_per_rad=UR_TICKS_PER_RAD,
                received_at=now,
                wall_time=recorded_at,
                delay_s=self._echo.delay_s,
            )
        )

    def _at_end(self) -> None:
        held = self._held
        if held is not None:
            self._emit_state(held[0], held[1], self.clock())


def recorded_profile(path: str | Path, fallback: RobotProfile) -> RobotProfile:
    """The robot profile a recording was made with (a UR's built from its arm), for what is
    loaded before the replay opens (the key map); `fallback` when the file cannot be read
    (opening the replay then says why)."""
    try:
        with Recording(path) as recording:
            return recording.profile(fallback)
    except RecordingError:
        return fallback
