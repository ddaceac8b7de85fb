"""The one receiver: robot datagrams to link events, and what the OCU sent to decoded commands.

Every reader of the wire goes through it — the live link (UDP or virtual), a replayed
recording, the recorder's decoded channels (through the link's events) and `ocu inspect` — so
what a replay shows is what the OCU decoded live. It decodes vendor and extension packets,
counts them (valid, malformed, rates, telemetry loss from the tick counter), drops telemetry
that comes late or twice, judges each reading's plausibility, measures the round trip from
the speed commands the robot echoes, detects the protocol extension, reassembles its video
fragments and decodes its range scans (ScanFrame). No Qt, no sockets, no clock of its own:
every call carries its time.

Thread-safe: the link's loop thread feeds received datagrams while the GUI thread's sends
are noted with `sent()`; the lock is never held while an event is emitted.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import replace
from enum import Enum

from ocu.control.plausibility import PlausibilityChecker
from ocu.link.delay import DelayEstimator
from ocu.link.reassembly import Reassembler
from ocu.link.stats import JitterMeter, LossEstimator, RateMeter, UplinkLossEstimator
from ocu.profile import RobotProfile
from ocu.protocol import ProtocolError, RemoteControlPacket, TelemetryPacket, VideoFramePacket
from ocu.protocol.extended import HelloPacket, ScanPacket, SequencedRcp, StatusPacket, VideoFragment
from ocu.protocol.mapping import (
    CommandMapper,
    commanded_motor_speeds,
    read_telemetry,
    scan_frame,
)
from ocu.protocol.wire import make_codec, make_extension_codec
from ocu.records import (
    OTHER,
    SCAN,
    STATUS,
    TELEMETRY,
    VIDEO,
    VIDEO_FRAGMENT,
    Command,
    DatagramReceived,
    ExtensionChanged,
    LinkEvent,
    LinkStats,
    ScanFrame,
    StatusFrame,
    TelemetryFrame,
    VideoFrame,
    VideoStats,
)

log = logging.getLogger("ocu.link")

# A telemetry tick this far (in seconds of ticks) below the newest one is a robot that
# restarted, not a late packet.
TICK_RESTART_S = 10.0
# A tick further ahead of the newest one than the time between their arrivals plus this is
# not the robot's clock (a corrupted or forged datagram): it needs a second packet to agree.
TICK_AHEAD_S = 2.0


class _Tick(Enum):
    """What a telemetry packet's tick says about the packet."""

    NEW = "new"  # newer than any so far: its readings are the latest
    STALE = "stale"  # a duplicate or a late one: older than what the OCU knows
    RESTART = "restart"  # the second of two agreeing on a new clock: the robot restarted
    JUNK = "junk"  # fits neither the robot's clock nor a pending restart


class Receiver:
    """Decodes one robot's datagrams into events for `emit` (see the module docstring).

    `extension` says whether the OCU probes for the protocol extension: without it, extension
    packets stay unknown types and count as malformed, as a vendor OCU would see them.
    `link_lost_after_s` is how long the extension may stay silent before it counts as gone.
    """

    def __init__(
        self,
        profile: RobotProfile,
        emit: Callable[[LinkEvent], None],
        *,
        extension: bool = False,
        link_lost_after_s: float | None = None,
    ) -> None:
        self.profile = profile
        self.emit = emit
        self._codec = make_codec(profile)
        ext_codec = make_extension_codec(profile)
        self._ext_codec = ext_codec if extension else None
        # What the OCU sent is decoded whatever it receives (a replay of an extended session).
        self._rcp_ext_codec = ext_codec if ext_codec is not None and ext_codec.rcp_type else None
        self._mapper = CommandMapper(profile)
        self.extension_timeout_s = (
            profile.link.link_lost_after_s if link_lost_after_s is None else link_lost_after_s
        )
        video = profile.video
        self._reassembler = Reassembler(
            video.reassembly_max_frames, video.reassembly_max_bytes, video.reassembly_timeout_s
        )
        self._lock = threading.Lock()
        self._received = 0
        self._telemetry = 0
        self._video = 0
        self._malformed = 0
        self._foreign = 0
        self._telemetry_rate = RateMeter()
        self._video_rate = RateMeter(window_s=1.0)
        self._loss = LossEstimator()
        self._delay = DelayEstimator()
        self._jitter = JitterMeter()
        self._uplink = UplinkLossEstimator()
        self._scan_rate = RateMeter()
        # When each camera's newest frame arrived (profile order).
        self._frame_at: list[float | None] = [None] * len(profile.link.camera_names)
        self._plausibility = PlausibilityChecker(profile)
        self._last_tick: int | None = None
        self._last_tick_at = 0.0
        # A tick that fit no clock, held until the next packet says whether it was a restart.
        self._new_clock: tuple[int, float] | None = None
        self._stale_telemetry = 0
        self._last_valid_at: float | None = None
        self._camera: int | None = None
        self._ext_active = False
        self._ext_last_at: float | None = None
        self.ext_received = 0
        self.ext_malformed = 0
        self.scans = 0

    # ---- what the OCU sent (any thread) -----------------------------------------------------

    def sent(self, data: bytes, at: float) -> Command | None:
        """A datagram the OCU put on the wire: the command it carried, if an RCP (vendor or
        sequenced).

        The camera it selected is where vendor video is shown; the motor speeds it asks for
        are what the robot will echo (the delay measurement).
        """
        if not data:
            return None
        rcp_ext = self._rcp_ext_codec
        try:
            if data[0] == self._codec.rcp_type:
                packet = RemoteControlPacket.decode(data, data[0])
            elif rcp_ext is not None and data[0] == rcp_ext.rcp_type:
                packet = SequencedRcp.decode(data, data[0]).rcp
            else:
                return None
        except ProtocolError:
            return None
        command = self._mapper.to_command(packet)
        echoes = commanded_motor_speeds(self.profile, command)
        with self._lock:
            if command.camera is not None:
                self._camera = command.camera
            self._delay.on_sent(at, echoes)
        return command

    # ---- what the robot sent (the link's loop thread) -------------------------------------

    def foreign(self) -> None:
        """A datagram from somebody other than the robot arrived (counted, not decoded)."""
        with self._lock:
            self._foreign += 1

    def received(self, data: bytes, at: float, wall: float) -> bool:
        """Decode one datagram from the robot and emit what it holds; whether it was valid.

        The raw datagram comes first (DatagramReceived, classified), then what it decoded to.
        """
        ext = self._ext_codec
        if ext is not None and data and ext.handles(data[0]):
            return self._extended(data, at, wall)
        try:
            packet = self._codec.decode(data)
        except ProtocolError as err:
            self.emit(DatagramReceived(data, at))
            with self._lock:
                self._malformed += 1
            log.debug("malformed datagram (%d bytes): %s", len(data), err)
            return False
        if isinstance(packet, RemoteControlPacket):
            self.emit(DatagramReceived(data, at))
            self.foreign()  # an RCP never comes from the robot
            return False
        verdict = None
        if isinstance(packet, TelemetryPacket):
            with self._lock:
                verdict = self._judge_tick(packet.tick, at)
            if verdict is _Tick.JUNK:
                # Counted (malformed) and dropped: it neither keeps the link alive nor enters
                # the loss figure, whose window it would poison for its whole length.
                self.emit(DatagramReceived(data, at))
                log.debug("telemetry tick %d fits no clock of the robot: dropped", packet.tick)
                return False
            robot_time_s = packet.tick / self.profile.link.telemetry_tick_hz
            self.emit(DatagramReceived(data, at, TELEMETRY, robot_time_s))
        else:
            self.emit(DatagramReceived(data, at, VIDEO))
        frame: TelemetryFrame | VideoFrame | None = None
        with self._lock:
            self._received += 1
            self._last_valid_at = at
            if isinstance(packet, TelemetryPacket):
                self._telemetry += 1
                self._telemetry_rate.add(at)
                if verdict is _Tick.RESTART:
                    log.info("telemetry ticks restarted at %d: robot restarted", packet.tick)
                    self._plausibility.reset()
                    self._loss.restart()
                    self._jitter.reset()  # its clock started over
                if verdict is _Tick.STALE:
                    self._stale_telemetry += 1
                else:
                    self._loss.add(packet.tick, at)
                    frame = self._telemetry_frame(packet, at, wall)
                # The delay's variation: arrival against the robot's own clock (its tick).
                # The clocks' offset cancels in the spread; late packets count too.
                self._jitter.add(at - packet.tick / self.profile.link.telemetry_tick_hz, at)
            elif isinstance(packet, VideoFramePacket):
                self._video += 1
                self._video_rate.add(at)
                frame = VideoFrame(packet.jpeg, self._camera, at, wall)
                self._frame_arrived(self._camera, at)
        if frame is not None:
            self.emit(frame)
        return True

    def _judge_tick(self, tick: int, at: float) -> _Tick:
        """What a telemetry tick arriving at `at` is (lock held); a NEW or RESTART one is kept.

        A tick not newer than the newest is a duplicate or came late (reordered), unless it is
        so far back that the robot restarted. One further ahead than the robot's clock can have
        run since the newest, or far back, is either a restart or junk (a corrupted or forged
        datagram, whose tick would hold back every real packet and poison the loss window):
        held, it becomes the new clock only when the next packet agrees with it.
        """
        hz = self.profile.link.telemetry_tick_hz
        last = self._last_tick
        if last is None:
            self._keep_tick(tick, at)
            return _Tick.NEW
        if tick <= last and last - tick < hz * TICK_RESTART_S:
            return _Tick.STALE
        if last < tick <= last + (at - self._last_tick_at + TICK_AHEAD_S) * hz:
            self._new_clock = None  # whatever was held did not agree: it was junk
            self._keep_tick(tick, at)
            return _Tick.NEW
        held = self._new_clock
        if held is not None and held[0] < tick <= held[0] + (at - held[1] + TICK_AHEAD_S) * hz:
            self._malformed -= 1  # the held one was the robot's after all: a late one now
            self._stale_telemetry += 1
            self._keep_tick(tick, at)
            return _Tick.RESTART
        self._new_clock = (tick, at)
        self._malformed += 1
        return _Tick.JUNK

    def _keep_tick(self, tick: int, at: float) -> None:
        self._last_tick = tick
        self._last_tick_at = at
        self._new_clock = None

    def _telemetry_frame(self, packet: TelemetryPacket, at: float, wall: float) -> TelemetryFrame:
        """Readings judged and the delay measured (lock held)."""
        readings = read_telemetry(self.profile, packet)
        for name, fault in self._plausibility.check(packet, readings).items():
            readings[name] = replace(readings[name], fault=fault)
        echoes = {record.device_id: record.speed_command for record in packet.motors}
        return TelemetryFrame(packet, readings, at, wall, self._delay.on_telemetry(at, echoes))

    def _extended(self, data: bytes, at: float, wall: float) -> bool:
        assert self._ext_codec is not None
        try:
            packet = self._ext_codec.decode(data)
        except ProtocolError as err:
            self.emit(DatagramReceived(data, at))
            with self._lock:
                self._malformed += 1
                self.ext_malformed += 1
            log.debug("malformed extension datagram (%d bytes): %s", len(data), err)
            return False
        if isinstance(packet, HelloPacket | SequencedRcp):
            self.emit(DatagramReceived(data, at, OTHER))
            self.foreign()  # a hello or an RCP never comes from the robot
            return False
        if isinstance(packet, VideoFragment):
            self.emit(DatagramReceived(data, at, VIDEO_FRAGMENT, packet.capture_time_us / 1e6))
        elif isinstance(packet, ScanPacket):
            self.emit(DatagramReceived(data, at, SCAN, packet.capture_time_us / 1e6))
        else:
            self.emit(DatagramReceived(data, at, STATUS))
        event: StatusFrame | VideoFrame | ScanFrame | None = None
        with self._lock:
            self._received += 1
            self.ext_received += 1
            self._last_valid_at = at
            self._ext_last_at = at
            became_active = not self._ext_active
            self._ext_active = True
            if isinstance(packet, VideoFragment):
                complete = self._reassembler.add(packet, at)
                if complete is not None:
                    self._video += 1
                    self._video_rate.add(at)
                    event = VideoFrame(
                        complete.jpeg,
                        complete.camera,
                        at,
                        wall,
                        sequence=complete.sequence,
                        capture_time_us=complete.capture_time_us,
                    )
                    self._frame_arrived(complete.camera, at)
            elif isinstance(packet, StatusPacket):
                event = StatusFrame(packet, at, wall)
                if packet.rcp_sequence is not None and packet.rcp_received is not None:
                    self._uplink.add(packet.rcp_sequence, packet.rcp_received, at)
            elif isinstance(packet, ScanPacket):
                self.scans += 1
                self._scan_rate.add(at)
                event = scan_frame(packet, at, wall)
        if became_active:
            log.info("robot speaks the protocol extension")
            self.emit(ExtensionChanged(True, "extension packets from the robot"))
        if event is not None:
            self.emit(event)
        return True

    def _frame_arrived(self, camera: int | None, at: float) -> None:
        """Note a camera's frame for its age (lock held); unknown cameras are not aged."""
        if camera is not None and 0 <= camera < len(self._frame_at):
            self._frame_at[camera] = at

    def expire(self, now: float) -> None:
        """Drop stale partial frames; notice an extension that went silent."""
        reason = None
        with self._lock:
            self._reassembler.expire(now)
            last = self._ext_last_at
            if self._ext_active and last is not None and now - last > self.extension_timeout_s:
                self._ext_active = False
                reason = f"no extension packet for {now - last:.1f} s: vendor protocol"
        if reason is not None:
            log.info("extension lost: %s", reason)
            self.emit(ExtensionChanged(False, reason))

    def robot_silent(self) -> None:
        """The link was lost: the robot may restart meanwhile (its ticks, readings, video)."""
        with self._lock:
            self._last_tick = None
            self._new_clock = None
            self._plausibility.reset()
            self._reassembler.reset()
            # What the robot echoes after the silence says nothing of the commands before it.
            self._delay.reset()
            self._jitter.reset()
            self._uplink.reset()

    # ---- state (any thread) ----------------------------------------------------------------

    @property
    def extension_active(self) -> bool:
        """Whether the robot speaks the protocol extension (valid packets lately)."""
        with self._lock:
            return self._ext_active

    @property
    def last_valid_at(self) -> float | None:
        """When the last valid packet from the robot arrived."""
        with self._lock:
            return self._last_valid_at

    def link_stats(
        self,
        now: float,
        *,
        sent: int,
        send_errors: int,
        rcp_rate_hz: float,
        send_rate_hz: float,
        estop_latched: bool,
    ) -> LinkStats:
        """The link's statistics now: the receiver's counters with the sender's given."""
        with self._lock:
            return LinkStats(
                sent=sent,
                received=self._received,
                telemetry=self._telemetry,
                video=self._video,
                malformed=self._malformed,
                foreign=self._foreign,
                send_errors=send_errors,
                rcp_rate_hz=rcp_rate_hz,
                telemetry_rate_hz=self._telemetry_rate.rate(now),
                video_rate_hz=self._video_rate.rate(now),
                loss_estimate=self._loss.loss(now),
                duplicates=self._loss.duplicates,
                reordered=self._loss.reordered,
                last_valid_age_s=None if self._last_valid_at is None else now - self._last_valid_at,
                send_rate_hz=send_rate_hz,
                estop_latched=estop_latched,
                delay_s=self._delay.estimate_s,
                stale_telemetry=self._stale_telemetry,
                jitter_s=self._jitter.jitter(now),
                uplink_loss=self._uplink.loss(now),
                scan_rate_hz=self._scan_rate.rate(now),
                frame_age_s=tuple(None if at is None else now - at for at in self._frame_at),
            )

    def video_stats(self) -> VideoStats:
        """Counters of the extension's fragment reassembly."""
        with self._lock:
            return self._reassembler.stats()
