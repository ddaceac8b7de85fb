"""The robot's side of the protocol: RCPs into the physics, telemetry and video frames out.

No sockets and no timers: the simulator hands it each datagram that got through the faults
and asks it, when due, for the next telemetry packet or video frame, which go to the sender
of the latest valid RCP. Extension hellos go to the ExtendedServer (ocu.sim.extended).

Telemetry motor records (raw units use the profile's telemetry scales):

- device state 1 = operational; operation mode 2 = velocity mode.
- position: the joint angle in ticks (`rad_to_ticks`), with the reading noise and raw
  position faults applied; position command: the same value, as the robot runs in velocity
  mode. Tracks report no position: both fields are 0.
- speed: the effective speed (joints in rad/s, tracks their belt speed in m/s) times
  `telemetry_speed_per_rad_s`; speed command: the speed the latest RCP asks for (zero after
  a watchdog stop) in the same units.
- current: idle + k*|speed| amperes times `telemetry_current_per_amp`; current command: the
  same model applied to the commanded speed.
- status bits:
  bit0 (0x1) at the lower limit,
  bit1 (0x2) at the upper limit,
  bit2 (0x4) stopped by the watchdog,
  bit3 (0x8) motion suppressed (waist commanded while the chassis moves).
"""

from __future__ import annotations

import logging
import math
import random
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from ocu.nav.geometry import Pose
from ocu.net.transport import Address
from ocu.profile import Motor, RobotProfile
from ocu.protocol import (
    MotorRecord,
    ProtocolError,
    RemoteControlPacket,
    TelemetryPacket,
    VideoFramePacket,
)
from ocu.protocol.extended import HelloPacket, SequencedRcp, sequence_newer
from ocu.protocol.mapping import CommandMapper, rad_to_ticks, speed_to_raw
from ocu.protocol.wire import make_codec, make_extension_codec
from ocu.sim.extended import ExtendedServer
from ocu.sim.physics import MotorReading, RobotPhysics
from ocu.sim.video import DEFAULT_QUALITY, FrameRenderer, quality_for_bitrate

log = logging.getLogger("ocu.sim")

# Sequence numbers remembered to count a duplicate datagram once (seconds of RCPs at 50 Hz).
RECENT_SEQUENCES = 256
STATUS_AT_LOWER_LIMIT = 0x1
STATUS_AT_UPPER_LIMIT = 0x2
STATUS_WATCHDOG_STOP = 0x4
STATUS_SUPPRESSED = 0x8
DEVICE_STATE_OPERATIONAL = 1
OPERATION_MODE_VELOCITY = 2

_I16_MIN = -32768
_I16_MAX = 32767


def _raw_i16(value: float) -> int:
    return int(min(max(round(value), _I16_MIN), _I16_MAX))


@dataclass
class RobotCounters:
    """What the robot made of the datagrams it got, and what it sent."""

    rcp: int = 0
    telemetry_sent: int = 0
    video_sent: int = 0
    malformed: int = 0
    foreign: int = 0
    # RCPs dropped as older than the newest applied (sequenced), or sent before the client's
    # sequenced ones (vendor RCPs while sequenced ones arrive).
    stale_rcp: int = 0


class RobotServer:
    """The vendor protocol over one RobotPhysics; called from the simulator's loop thread,
    except for the reading faults (set_noise_deg, set_raw_position), which lock.
    """

    def __init__(
        self,
        profile: RobotProfile,
        physics: RobotPhysics,
        renderer: FrameRenderer,
        extension: ExtendedServer | None = None,
        *,
        seed: int | None = None,
        noise_deg: float = 0.0,
    ) -> None:
        self.profile = profile
        self.physics = physics
        self.extension = extension
        self.counters = RobotCounters()
        self._codec = make_codec(profile)
        self._mapper = CommandMapper(profile)
        self._renderer = renderer
        # A vendor-mode robot still knows the extension's frame types, to count such packets
        # as foreign rather than as malformed.
        self._ext_codec = (
            extension.codec if extension is not None else make_extension_codec(profile)
        )
        self._faults_lock = threading.Lock()
        self._noise_rad = 0.0
        self._noise_rng = random.Random(seed)
        self._raw_faults: dict[str, int] = {}
        self.set_noise_deg(noise_deg)
        self.client: Address | None = None
        self.torch = False
        self.camera = 0
        self.video_quality = DEFAULT_QUALITY
        self._bad_camera: int | None = None
        self._frame_number = 0
        # The newest sequenced RCP applied: its client, number and arrival time.
        self._sequenced: tuple[Address, int, float] | None = None
        self.applied_sequence: int | None = None
        # Distinct sequenced RCPs received, applied or dropped as late (u32, wrapping): echoed
        # in the status packet with the newest applied one's number, so the OCU can tell how
        # many of its commands the link lost. A duplicate (the same number again) counts once.
        self.sequenced_received = 0
        self._recent_sequences: deque[int] = deque(maxlen=RECENT_SEQUENCES)
        self._recent_set: set[int] = set()

    # ---- reading faults (any thread) --------------------------------------------------------

    def set_raw_position(self, joint: str, raw: int | None) -> None:
        """Report this raw position for a joint (a broken encoder); None: the true one again."""
        motor = self.profile.motors.get(joint)
        if motor is None or not motor.has_position:
            raise ValueError(f"{joint!r} is not a motor with a position")
        if raw is not None and not 0 <= raw <= 0xFFFFFFFF:
            raise ValueError(f"raw position must be a u32, got {raw!r}")
        with self._faults_lock:
            if raw is None:
                self._raw_faults.pop(joint, None)
            else:
                self._raw_faults[joint] = raw
        log.info("%s reports raw position %s", joint, "truly" if raw is None else f"0x{raw:08x}")

    def set_noise_deg(self, noise_deg: float) -> None:
        """Reported positions get uniform noise of ±noise_deg (the true angle is unchanged)."""
        if not (math.isfinite(noise_deg) and noise_deg >= 0.0):
            raise ValueError(f"noise_deg must be >= 0, got {noise_deg!r}")
        with self._faults_lock:
            self._noise_rad = math.radians(noise_deg)

    # ---- datagrams in -----------------------------------------------------------------------

    def receive(self, data: bytes, address: Address, now_s: float) -> RemoteControlPacket | None:
        """Take one datagram; returns the RCP it carried once applied, None for anything else."""
        if data and self._ext_codec is not None and self._ext_codec.handles(data[0]):
            return self._receive_extended(data, address, now_s)
        try:
            packet = self._codec.decode(data)
        except ProtocolError as err:
            self.counters.malformed += 1
            log.debug("dropped malformed datagram from %s:%d: %s", address[0], address[1], err)
            return None
        if not isinstance(packet, RemoteControlPacket):
            self.counters.foreign += 1
            log.debug("dropped %s from %s:%d", type(packet).__name__, address[0], address[1])
            return None
        if self._sequencing(address, now_s):
            # Sent before the client's first sequenced RCP and delivered after it: stale.
            self.counters.stale_rcp += 1
            return None
        self.applied_sequence = None
        self._apply(packet, address, now_s)
        return packet

    def _sequencing(self, address: Address, now_s: float) -> bool:
        """Whether this client's sequenced RCPs are current (within the robot's watchdog)."""
        last = self._sequenced
        return (
            last is not None
            and last[0] == address
            and now_s - last[2] <= self.profile.link.robot_watchdog_s
        )

    def _receive_sequenced(
        self, packet: SequencedRcp, address: Address, now_s: float
    ) -> RemoteControlPacket | None:
        """Apply a sequenced RCP unless it is older than the newest applied from its client.

        A new client, or one silent for the watchdog time (the robot stopped meanwhile),
        starts a new sequence: an OCU that restarted begins wherever it likes.
        """
        last = self._sequenced
        current = self._sequencing(address, now_s) and last is not None
        if not current:
            self._recent_sequences.clear()
            self._recent_set.clear()
        if packet.sequence not in self._recent_set:
            if len(self._recent_sequences) == RECENT_SEQUENCES:
                self._recent_set.discard(self._recent_sequences[0])
            self._recent_sequences.append(packet.sequence)
            self._recent_set.add(packet.sequence)
            self.sequenced_received = (self.sequenced_received + 1) % 2**32
        if current and last is not None and not sequence_newer(packet.sequence, last[1]):
            self.counters.stale_rcp += 1
            log.debug("dropped RCP #%d: #%d already applied", packet.sequence, last[1])
            return None
        self._sequenced = (address, packet.sequence, now_s)
        self.applied_sequence = packet.sequence
        self._apply(packet.rcp, address, now_s)
        return packet.rcp

    def _receive_extended(
        self, data: bytes, address: Address, now_s: float
    ) -> RemoteControlPacket | None:
        if self.extension is None or self._ext_codec is None:
            # A vendor robot does not speak the extension: dropped like any foreign packet.
            self.counters.foreign += 1
            return None
        try:
            packet = self._ext_codec.decode(data)
        except ProtocolError as err:
            self.counters.malformed += 1
            log.debug("dropped malformed extension datagram: %s", err)
            return None
        if isinstance(packet, SequencedRcp):
            return self._receive_sequenced(packet, address, now_s)
        if not isinstance(packet, HelloPacket):
            self.counters.foreign += 1
            return None
        if not self.extension.active(now_s):
            log.info("extension hello from %s:%d", *address)
        self.extension.on_hello(packet, address, now_s)
        return None

    def _apply(self, packet: RemoteControlPacket, address: Address, now_s: float) -> None:
        command = self._mapper.to_command(packet)
        self.counters.rcp += 1
        if address != self.client:
            log.info("new client %s:%d", *address)
            self.client = address
        self.physics.apply(command, now_s)
        if command.torch != self.torch:
            self.torch = command.torch
            log.info("torch %s", "on" if command.torch else "off")
        self._select_camera(command.camera)
        self.video_quality = quality_for_bitrate(command.video_bitrate)

    def _select_camera(self, camera: int | None) -> None:
        if camera is None or camera == self.camera:
            return
        names = self.profile.link.camera_names
        if camera >= len(names):
            if camera != self._bad_camera:
                log.warning("ignored selection of camera %d: only %d cameras", camera, len(names))
                self._bad_camera = camera
            return
        self.camera = camera
        log.info("camera %d (%s) selected", camera, names[camera])

    # ---- datagrams out ----------------------------------------------------------------------

    def telemetry(self, now_s: float, uptime_s: float) -> tuple[bytes, Address] | None:
        """The telemetry packet of now_s for the client; None before the first RCP."""
        if self.client is None:
            return None
        self.physics.advance(now_s)
        tick = int(uptime_s * self.profile.link.telemetry_tick_hz)
        records = tuple(self._motor_record(motor) for motor in self.profile.motors.values())
        self.counters.telemetry_sent += 1
        return self._codec.encode(TelemetryPacket(tick=tick, motors=records)), self.client

    def _motor_record(self, motor: Motor) -> MotorRecord:
        reading = self.physics.reading(motor)
        position = 0
        if reading.angle_rad is not None:
            with self._faults_lock:
                noise_rad, raw_fault = self._noise_rad, self._raw_faults.get(motor.name)
            reported_rad = reading.angle_rad
            if noise_rad > 0.0:
                reported_rad += self._noise_rng.uniform(-noise_rad, noise_rad)
            position = rad_to_ticks(motor, reported_rad) if raw_fault is None else raw_fault
        current_scale = self.profile.telemetry_current_per_amp
        return MotorRecord(
            device_id=motor.device_id,
            state=DEVICE_STATE_OPERATIONAL,
            mode=OPERATION_MODE_VELOCITY,
            position=position,
            speed=speed_to_raw(self.profile, reading.speed),
            current=_raw_i16(reading.current_a * current_scale),
            status=_status(reading),
            position_command=position,
            speed_command=speed_to_raw(self.profile, reading.speed_command),
            current_command=_raw_i16(reading.current_command_a * current_scale),
        )

    def video_frame(self, now_s: float) -> tuple[bytes, Address] | None:
        """The vendor video frame of now_s for the client; None when it gets none."""
        if self.client is None:
            return None
        if self.extension is not None and self.extension.active(now_s):
            return None  # the client gets every camera through the extension instead
        jpeg = self._renderer.render(
            self.camera,
            self._frame_number,
            self.video_quality,
            torch=self.torch,
            time_s=now_s,
            pose=Pose(*self.physics.pose),
            joints_rad=self.physics.joints_rad,
        )
        self._frame_number += 1
        self.counters.video_sent += 1
        return self._codec.encode(VideoFramePacket(jpeg=jpeg)), self.client

    def poll_extension(self, now_s: float, send: Callable[[bytes, Address], None]) -> None:
        """Let the extension send what is due (status, camera fragments)."""
        if self.extension is None:
            return
        self.extension.poll(
            now_s,
            send,
            torch=self.torch,
            pose=self.physics.pose,
            moving=not self.physics.all_stopped,
            rcp_quality=self.video_quality,
            joints_rad=self.physics.joints_rad,
            rcp_echo=(
                None if self._sequenced is None else (self._sequenced[1], self.sequenced_received)
            ),
        )

    def next_due_s(self) -> float:
        """When poll_extension() next has something to send."""
        return math.inf if self.extension is None else self.extension.next_due_s()


def _status(reading: MotorReading) -> int:
    status = STATUS_WATCHDOG_STOP if reading.watchdog_stopped else 0
    if reading.at_lower_limit:
        status |= STATUS_AT_LOWER_LIMIT
    if reading.at_upper_limit:
        status |= STATUS_AT_UPPER_LIMIT
    if reading.suppressed:
        status |= STATUS_SUPPRESSED
    return status
