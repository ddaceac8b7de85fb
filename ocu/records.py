"""The record types that cross the seams: commands in, link events out (no Qt, no sockets).

Everything that talks to the robot speaks these: the link implementations (UDP, virtual,
replay) emit `LinkEvent`s to their listeners, the console model and the ROS bridge turn
operator and planner input into `Command`s. A listener is any callable taking one event; it
looks at the types it cares about and ignores the rest. They belong to no robot's protocol:
a link turns its wire's packets into them (the Engineer's: ocu.protocol.mapping), and nothing
above the links imports a wire's types (import-linter contracts in pyproject.toml).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import Protocol

# ---- commands ----------------------------------------------------------------------------


class CommandError(ValueError):
    """A command names a channel the profile lacks or holds a value that is not finite."""


@dataclass(frozen=True)
class Command:
    """What the OCU asks of the robot: channel velocities (m/s or rad/s) and switches.

    `until` gives some channels an end: the link sends that channel's velocity until the
    monotonic time given, then zero, whether or not a newer command comes (a position
    controller's motion ends where the target is even when its next tick is late). A channel
    without an entry runs until the next command.

    `goals` gives some of those channels a position command with a duration: the joint's
    angle (rad) the robot is to reach at the channel's `until`, by one move of its own, on
    hardware with the capability "timed_moves" (a board that takes "go to P within T"). The
    channel's velocity is then the mean speed of that move: a link without timed moves sends
    it until `until`, which ends at the same angle, and the position controller's prediction
    integrates it as it integrates any velocity.
    """

    velocities: Mapping[str, float] = field(default_factory=dict)
    torch: bool = False
    camera: int | None = None
    video_bitrate: float = 0.0
    until: Mapping[str, float] = field(default_factory=dict)
    goals: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # Which channels exist is the profile's business (CommandMapper checks them).
        for name, value in self.velocities.items():
            if not math.isfinite(value):
                raise CommandError(f"{name}: velocity must be finite, got {value!r}")
        for name, at in self.until.items():
            if not math.isfinite(at):
                raise CommandError(f"{name}: the end of its motion must be finite, got {at!r}")
        for name, goal in self.goals.items():
            if not math.isfinite(goal) or name not in self.until:
                raise CommandError(f"{name}: a goal must be finite and have an end, got {goal!r}")
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
        """A copy with one channel changed (and no end: it runs until the next command)."""
        return self.with_velocities({channel: value})

    def with_velocities(self, values: Mapping[str, float]) -> Command:
        """A copy with several channels changed (those without an end from now on)."""
        velocities = dict(self.velocities)
        velocities.update(values)
        until = {name: at for name, at in self.until.items() if name not in values}
        goals = {name: at for name, at in self.goals.items() if name not in values}
        return replace(self, velocities=velocities, until=until, goals=goals)

    def stopped(self) -> Command:
        """The same switches with every velocity zero (the e-stop command)."""
        return replace(self, velocities={}, until={}, goals={})

    def expired(self, now: float) -> Command:
        """This command at `now`: the channels whose end has come are zero (self if none)."""
        ended = {name for name, at in self.until.items() if at <= now}
        if not ended:
            return self
        return replace(
            self,
            velocities={n: v for n, v in self.velocities.items() if n not in ended},
            until={n: at for n, at in self.until.items() if n not in ended},
            goals={n: at for n, at in self.goals.items() if n not in ended},
        )

    def same_wire(self, other: Command) -> bool:
        """Whether the two send the same now (they may differ in when channels end)."""
        return (
            {n: v for n, v in self.velocities.items() if v != 0.0}
            == {n: v for n, v in other.velocities.items() if v != 0.0}
            and self.goals == other.goals
            and self.torch == other.torch
            and self.camera == other.camera
            and self.video_bitrate == other.video_bitrate
        )

    @property
    def next_end(self) -> float | None:
        """The earliest end of a moving channel (None: none ends by itself)."""
        ends = [at for name, at in self.until.items() if self.velocities.get(name, 0.0) != 0.0]
        return min(ends, default=None)


# ---- video streams ------------------------------------------------------------------------


class StreamRequestError(ValueError):
    """A camera stream request holds a value out of its range."""


def _check_range(name: str, value: int, low: int, high: int) -> None:
    if not isinstance(value, int) or isinstance(value, bool):
        raise StreamRequestError(f"{name}={value!r} is not an integer")
    if not low <= value <= high:
        raise StreamRequestError(f"{name}={value} out of range [{low}, {high}]")


@dataclass(frozen=True)
class CameraRequest:
    """What the OCU asks of one camera; fps 0 switches it off, quality 0 follows the command."""

    camera: int
    width_px: int
    height_px: int
    fps: int
    quality: int = 0

    def check(self) -> None:
        """StreamRequestError unless every field is in its range."""
        _check_range("camera", self.camera, 0, 254)
        _check_range("width_px", self.width_px, 1, 65535)
        _check_range("height_px", self.height_px, 1, 65535)
        _check_range("fps", self.fps, 0, 255)
        _check_range("quality", self.quality, 0, 100)


@dataclass(frozen=True)
class StreamRequest:
    """The per-camera streams a link asks of the robot, and the largest datagram it takes."""

    cameras: tuple[CameraRequest, ...] = ()
    max_datagram_bytes: int = 1472


@dataclass(frozen=True)
class VideoStats:
    """Counters of a link's video frame reassembly; `frames_held`, `bytes_held` are current.

    truncated: partial frames given up with fragments missing (superseded by a newer frame
    of the camera, or evicted by the bounds); expired: partial frames that timed out;
    out_of_order: frames (or their fragments) older than the newest delivered for the camera;
    inconsistent: fragments whose header contradicts the rest of their frame.
    """

    fragments: int = 0
    completed: int = 0
    duplicates: int = 0
    truncated: int = 0
    evicted: int = 0
    expired: int = 0
    out_of_order: int = 0
    inconsistent: int = 0
    restarts: int = 0
    frames_held: int = 0
    bytes_held: int = 0


# ---- telemetry ---------------------------------------------------------------------------


class RawMotor(Protocol):
    """One motor's record as the robot sent it (raw units), whatever the wire."""

    @property
    def device_id(self) -> int: ...
    @property
    def state(self) -> int: ...
    @property
    def mode(self) -> int: ...
    @property
    def position(self) -> int: ...
    @property
    def status(self) -> int: ...


class RawTelemetry(Protocol):
    """A telemetry frame as the robot sent it: the robot's tick and its motor records."""

    @property
    def tick(self) -> int: ...
    @property
    def motors(self) -> Sequence[RawMotor]: ...


class RawStatus(Protocol):
    """A status report as the robot sent it (None: not measured)."""

    @property
    def voltage_mv(self) -> int | None: ...
    @property
    def charge_permille(self) -> int | None: ...
    @property
    def headlight_on(self) -> bool | None: ...
    @property
    def roll_mrad(self) -> int | None: ...
    @property
    def pitch_mrad(self) -> int | None: ...
    @property
    def yaw_mrad(self) -> int | None: ...


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
    """One decoded telemetry frame (`packet`: as the robot sent it) with its SI readings.

    Readings the OCU does not believe carry their `fault`. `delay_s` is the round trip this
    packet took by the link's measurement (ocu.link.delay): the reading was taken when the
    commands sent `delay_s` before `received_at` had reached the robot. None: not known.
    """

    packet: RawTelemetry
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
    """One status report in SI units (None = the robot did not measure it)."""

    packet: RawStatus
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
    # A link that reconnects by itself (a UR's TCP): attempts that failed since the link was
    # lost, and the seconds until the next one (None: connected, or it does not reconnect).
    reconnect_failures: int = 0
    next_attempt_in_s: float | None = None

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
    """The link stopped the robot by itself or on request (e-stop, watchdogs, link lost).

    `stopped` False: news of the robot's own safety that stopped nothing (a controller that
    takes motion again after its stop): shown, and the model halts nothing for it.
    """

    message: str
    stopped: bool = True


@dataclass(frozen=True)
class RobotModeReport:
    """The robot controller's own mode, where it reports one (a UR: its robot mode, safety
    mode and stops): whether it takes motion now. The link sends one when it changes."""

    mode: str  # "RUNNING", "POWER_OFF", ...
    safety: str  # "NORMAL", "REDUCED", "PROTECTIVE_STOP", ...
    may_move: bool
    stops: tuple[str, ...] = ()  # "emergency stop", "protective stop"

    @property
    def text(self) -> str:
        """The status bar's words: "RUNNING · NORMAL", "PROTECTIVE STOP", ..."""
        if self.stops:
            return " · ".join(stop.upper() for stop in self.stops)
        return f"{self.mode} · {self.safety}".replace("_", " ")


# What a raw datagram was, for recordings (DatagramSent.kind, DatagramReceived.kind).
RCP = "rcp"
HELLO = "hello"
TELEMETRY = "telemetry"
VIDEO = "video"
VIDEO_FRAGMENT = "video_fragment"
STATUS = "status"
SCAN = "scan"
OTHER = "other"
# A UR controller's (ocu.link.ur): URScript sent, and the packets of its three TCP ports.
UR_SCRIPT = "ur_script"
UR_PRIMARY = "ur_primary"
UR_SECONDARY = "ur_secondary"
UR_REALTIME = "ur_realtime"
# An xArm board's (ocu.link.xarm): each frame written to it, each whole frame read from it.
XARM_TO_BOARD = "xarm_to_board"
XARM_FROM_BOARD = "xarm_from_board"


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
    | RobotModeReport
    | DatagramSent
    | DatagramReceived
    | CommandSent
)
Listener = Callable[[LinkEvent], None]
