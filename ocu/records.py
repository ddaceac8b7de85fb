"""The record types that cross the seams: commands in, link events out (no Qt, no sockets).

Everything that talks to the robot speaks these: the link implementations (UDP, virtual,
replay) emit `LinkEvent`s to their listeners, the console model and the ROS bridge turn
operator and planner input into `Command`s. A listener is any callable taking one event; it
looks at the types it cares about and ignores the rest.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from enum import Enum

from ocu.protocol import TelemetryPacket
from ocu.protocol.extended import SCAN_INVALID, SCAN_NO_RETURN, ScanPacket, StatusPacket

# ---- commands ----------------------------------------------------------------------------


class CommandError(ValueError):
    """A command names a channel the profile lacks or holds a value that is not finite."""


@dataclass(frozen=True)
class Command:
    """What the OCU asks of the robot: channel velocities (m/s or rad/s) and switches."""

    velocities: Mapping[str, float] = field(default_factory=dict)
    torch: bool = False
    camera: int | None = None
    video_bitrate: float = 0.0

    def __post_init__(self) -> None:
        # Which channels exist is the profile's business (CommandMapper checks them).
        for name, value in self.velocities.items():
            if not math.isfinite(value):
                raise CommandError(f"{name}: velocity must be finite, got {value!r}")
        if self.camera is not None and not 0 <= self.camera < 255:
            raise CommandError(f"camera index must be in [0, 254], got {self.camera}")

    def velocity(self, channel: str) -> float:
        """Velocity of one channel; 0.0 when unset."""
        return float(self.velocities.get(channel, 0.0))

    @property
    def is_motion(self) -> bool:
        """Whether any channel asks for movement."""
        return any(v != 0.0 for v in self.velocities.values())

    def with_velocity(self, channel: str, value: float) -> Command:
        """A copy with one channel changed."""
        velocities = dict(self.velocities)
        velocities[channel] = value
        return replace(self, velocities=velocities)

    def with_velocities(self, values: Mapping[str, float]) -> Command:
        """A copy with several channels changed."""
        velocities = dict(self.velocities)
        velocities.update(values)
        return replace(self, velocities=velocities)

    def stopped(self) -> Command:
        """The same switches with every velocity zero (the e-stop command)."""
        return replace(self, velocities={})


# ---- telemetry ---------------------------------------------------------------------------


@dataclass(frozen=True)
class JointReading:
    """One motor's telemetry in SI units."""

    name: str
    device_id: int
    state: int
    mode: int
    angle_rad: float | None
    speed_rad_s: float
    current_a: float
    status: int
    target_angle_rad: float | None
    speed_command_rad_s: float
    current_command_a: float
    # Why the OCU does not believe this reading (ocu.control.plausibility); None: plausible.
    fault: str | None = None

    @property
    def plausible(self) -> bool:
        """Whether the reading may be acted on."""
        return self.fault is None


@dataclass(frozen=True)
class TelemetryFrame:
    """One decoded telemetry packet with its SI readings and arrival times.

    Readings the OCU does not believe carry their `fault`. `delay_s` is the round trip this
    packet took by the link's measurement (ocu.link.delay): the reading was taken when the
    commands sent `delay_s` before `received_at` had reached the robot. None: not known.
    """

    packet: TelemetryPacket
    readings: dict[str, JointReading]
    received_at: float
    wall_time: float
    delay_s: float | None = None

    @property
    def faults(self) -> dict[str, str]:
        """Joint name to why its reading is implausible."""
        return {name: r.fault for name, r in self.readings.items() if r.fault is not None}


@dataclass(frozen=True)
class VideoFrame:
    """One JPEG frame from the robot and when it arrived.

    A vendor frame carries no camera id: `camera` is the camera the OCU last selected (None
    before any selection). An extension frame carries its camera, sequence number and the
    robot's capture time (microseconds of the robot's monotonic clock).
    """

    jpeg: bytes
    camera: int | None
    received_at: float
    wall_time: float
    sequence: int | None = None
    capture_time_us: int | None = None


@dataclass(frozen=True)
class StatusFrame:
    """One extension status packet in SI units (None = the robot did not measure it)."""

    packet: StatusPacket
    received_at: float
    wall_time: float

    @property
    def voltage_v(self) -> float | None:
        """Battery voltage in volts."""
        mv = self.packet.voltage_mv
        return None if mv is None else mv / 1000.0

    @property
    def charge_percent(self) -> float | None:
        """Battery charge in percent."""
        permille = self.packet.charge_permille
        return None if permille is None else permille / 10.0

    @property
    def headlight_on(self) -> bool | None:
        """Headlight state as the robot reports it."""
        return self.packet.headlight_on

    @property
    def roll_rad(self) -> float | None:
        """Roll angle in radians."""
        mrad = self.packet.roll_mrad
        return None if mrad is None else mrad / 1000.0

    @property
    def pitch_rad(self) -> float | None:
        """Pitch angle in radians."""
        mrad = self.packet.pitch_mrad
        return None if mrad is None else mrad / 1000.0

    @property
    def yaw_rad(self) -> float | None:
        """The IMU's heading in radians (counter-clockwise; its zero is the IMU's own)."""
        mrad = self.packet.yaw_mrad
        return None if mrad is None else mrad / 1000.0


# Where a scan came from: the robot over the protocol extension, or another ROS node.
SCAN_FROM_ROBOT = "robot"
SCAN_FROM_ROS = "ros"


@dataclass(frozen=True)
class ScanFrame:
    """One planar range scan in SI units, in the sensor's frame (x forward, y left).

    Beam k points at `angle_min_rad + k * angle_increment_rad`; its range is in metres,
    `math.inf` when nothing was within `range_max_m`, `math.nan` when it measured nothing.
    """

    angle_min_rad: float
    angle_increment_rad: float
    range_min_m: float
    range_max_m: float
    ranges_m: tuple[float, ...]
    received_at: float
    wall_time: float
    source: str = SCAN_FROM_ROBOT
    sequence: int | None = None
    capture_time_us: int | None = None

    @classmethod
    def from_packet(cls, packet: ScanPacket, received_at: float, wall_time: float) -> ScanFrame:
        """The scan a robot sent, in metres and radians."""
        ranges = tuple(
            math.inf if raw == SCAN_NO_RETURN else math.nan if raw == SCAN_INVALID else raw / 1e3
            for raw in packet.ranges_mm
        )
        return cls(
            angle_min_rad=packet.angle_min_urad / 1e6,
            angle_increment_rad=packet.angle_increment_urad / 1e6,
            range_min_m=packet.range_min_mm / 1e3,
            range_max_m=packet.range_max_mm / 1e3,
            ranges_m=ranges,
            received_at=received_at,
            wall_time=wall_time,
            source=SCAN_FROM_ROBOT,
            sequence=packet.sequence,
            capture_time_us=packet.capture_time_us,
        )


# ---- the link ----------------------------------------------------------------------------


class LinkState(Enum):
    """Whether valid packets are arriving from the robot (machine values, not display text)."""

    CONNECTING = "connecting"
    CONNECTED = "connected"
    LOST = "lost"
    CLOSED = "closed"

    @property
    def label(self) -> str:
        """How messages and diagnostics name the state ("LINK LOST" stands out)."""
        return "LINK LOST" if self is LinkState.LOST else self.value

    @classmethod
    def parse(cls, text: str) -> LinkState | None:
        """A state from its value; also the display text older recordings stored."""
        legacy = {"LINK LOST": "lost"}
        try:
            return cls(legacy.get(text, text))
        except ValueError:
            return None


@dataclass(frozen=True)
class LinkStats:
    """A snapshot of the link's counters and rates."""

    sent: int
    received: int
    telemetry: int
    video: int
    malformed: int
    foreign: int
    send_errors: int
    rcp_rate_hz: float
    telemetry_rate_hz: float
    video_rate_hz: float
    loss_estimate: float | None
    duplicates: int
    reordered: int
    last_valid_age_s: float | None
    send_rate_hz: float
    estop_latched: bool
    # Round trip measured from the robot's echoed speed commands (ocu.link.delay); None:
    # nothing measured yet. Telemetry packets dropped for coming late or twice.
    delay_s: float | None = None
    stale_telemetry: int = 0
    # How much the link's delay varies: the standard deviation over the last 10 s of each
    # telemetry packet's arrival less its tick, the robot's clock (None: too few packets).
    # Range scans received per second. Per camera (profile order): seconds since its newest
    # frame arrived, None before its first frame.
    jitter_s: float | None = None
    scan_rate_hz: float = 0.0
    frame_age_s: tuple[float | None, ...] = ()
    # Share of the commands (sequenced RCPs) sent over the last 30 s that the robot did not
    # apply, from its echo (ocu.link.stats.UplinkLossEstimator); None: no robot echo.
    uplink_loss: float | None = None

    @classmethod
    def empty(cls, send_rate_hz: float = 0.0) -> LinkStats:
        """Nothing counted yet."""
        return cls(0, 0, 0, 0, 0, 0, 0, 0.0, 0.0, 0.0, None, 0, 0, None, send_rate_hz, False)


@dataclass(frozen=True)
class LinkStateChanged:
    """The link changed state, and why."""

    state: LinkState
    reason: str


@dataclass(frozen=True)
class ExtensionChanged:
    """The robot started or stopped speaking the protocol extension."""

    active: bool
    reason: str


@dataclass(frozen=True)
class SafetyEvent:
    """The link stopped the robot by itself or on request (e-stop, watchdogs, link lost)."""

    message: str


# What a raw datagram was, for recordings (DatagramSent.kind, DatagramReceived.kind).
RCP = "rcp"
HELLO = "hello"
TELEMETRY = "telemetry"
VIDEO = "video"
VIDEO_FRAGMENT = "video_fragment"
STATUS = "status"
SCAN = "scan"
OTHER = "other"


@dataclass(frozen=True)
class DatagramSent:
    """A datagram went on the wire (recording): an RCP, a hello or something else."""

    data: bytes
    sent_at: float
    kind: str = OTHER


@dataclass(frozen=True)
class DatagramReceived:
    """A datagram from the robot arrived, valid or not (recording).

    `kind` is what the receiver found it to be (OTHER when it was malformed or unknown);
    `robot_time_s` the robot's own stamp where the packet carries one (the telemetry tick,
    a video fragment's capture time), in seconds of the robot's clock.
    """

    data: bytes
    received_at: float
    kind: str = OTHER
    robot_time_s: float | None = None


@dataclass(frozen=True)
class CommandSent:
    """The command an RCP that went on the wire carried, decoded (recording, replay)."""

    command: Command
    sent_at: float


LinkEvent = (
    TelemetryFrame
    | VideoFrame
    | StatusFrame
    | ScanFrame
    | LinkStats
    | LinkStateChanged
    | ExtensionChanged
    | SafetyEvent
    | DatagramSent
    | DatagramReceived
    | CommandSent
)
Listener = Callable[[LinkEvent], None]
