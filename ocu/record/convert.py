"""Link events into ROS 2 messages: the one conversion the recorder and the live server share.

`item_of` turns a link event into a small tuple (kind, monotonic time, payload...) cheap
enough to queue on the link's threads; `MessageConverter.convert` turns one such item into
its message(s) as plain dicts (the CDR encoders of ocu.record.schemas take them) and hands
each to a sink with its topic, so a file and a socket carry the same bytes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Final, Protocol

from ocu import records as r
from ocu.profile import RobotProfile
from ocu.record import schemas as s
from ocu.records import (
    Command,
    CommandSent,
    DatagramReceived,
    DatagramSent,
    ExtensionChanged,
    LinkEvent,
    LinkStateChanged,
    LinkStats,
    RobotModeReport,
    SafetyEvent,
    StatusFrame,
    TelemetryFrame,
    VideoFrame,
)

# What the recorder queues: (kind, monotonic time, payload...). The kinds:
SENT: Final = 0
RECEIVED: Final = 1
TELEMETRY: Final = 2
VIDEO: Final = 3
STATUS: Final = 4
STATS: Final = 5
EVENT: Final = 6
COMMAND: Final = 7

# The raw channel of each kind of datagram (ocu.records).
SENT_TOPICS = {
    r.RCP: s.RAW_RCP,
    r.HELLO: s.RAW_HELLO,
    r.UR_SCRIPT: s.RAW_UR_SCRIPT,
    r.XARM_TO_BOARD: s.RAW_XARM_TO_BOARD,
}
RECEIVED_TOPICS = {
    r.TELEMETRY: s.RAW_TELEMETRY,
    r.VIDEO: s.RAW_VIDEO,
    r.VIDEO_FRAGMENT: s.RAW_VIDEO_FRAGMENT,
    r.STATUS: s.RAW_STATUS,
    r.SCAN: s.RAW_SCAN,
    r.UR_PRIMARY: s.RAW_UR_PRIMARY,
    r.UR_SECONDARY: s.RAW_UR_SECONDARY,
    r.UR_REALTIME: s.RAW_UR_REALTIME,
    r.XARM_FROM_BOARD: s.RAW_XARM_FROM_BOARD,
}

# The decoded channels every recording has, with their types (cameras come from the profile).
DECODED_TOPICS: Final = (
    (s.CMD_VEL, s.TWIST),
    (s.CMD_JOINTS, s.JOINT_STATE),
    (s.JOINT_STATES, s.JOINT_STATE),
    (s.LINK_STATS, s.LINK_STATS_TYPE),
    (s.EVENTS, s.EVENT),
    (s.ROBOT_STATUS, s.ROBOT_STATUS_TYPE),
)

# Rough bytes of a telemetry item (its readings), for the queues' memory bounds.
TELEMETRY_ITEM_BYTES = 2000

Item = tuple[Any, ...]


class Sink(Protocol):
    """Where converted messages go: (monotonic time, topic, message, publish time ns)."""

    def __call__(
        self, mono: float, topic: str, message: dict[str, Any], publish_ns: int | None = None
    ) -> None: ...


def item_of(event: LinkEvent, clock: Callable[[], float]) -> tuple[Item, int] | None:
    """The queue item of one link event and its payload's size in bytes (None: not kept)."""
    if isinstance(event, DatagramSent):
        return (SENT, event.sent_at, event), len(event.data)
    if isinstance(event, DatagramReceived):
        return (RECEIVED, event.received_at, event), len(event.data)
    if isinstance(event, CommandSent):
        return (COMMAND, event.sent_at, event.command), 0
    if isinstance(event, TelemetryFrame):
        return (TELEMETRY, event.received_at, event), TELEMETRY_ITEM_BYTES
    if isinstance(event, VideoFrame):
        return (VIDEO, event.received_at, event), len(event.jpeg)
    if isinstance(event, StatusFrame):
        return (STATUS, event.received_at, event), 0
    if isinstance(event, LinkStats):
        return (STATS, clock(), event), 0
    if isinstance(event, LinkStateChanged):
        return (EVENT, clock(), s.EVENT_LINK_STATE, event.state.value, event.reason), 0
    if isinstance(event, SafetyEvent):
        return (EVENT, clock(), s.EVENT_SAFETY, "", event.message), 0
    if isinstance(event, ExtensionChanged):
        state = "active" if event.active else "inactive"
        return (EVENT, clock(), s.EVENT_EXTENSION, state, event.reason), 0
    if isinstance(event, RobotModeReport):
        detail = f"robot {event.mode}, safety {event.safety}"
        detail += "".join(f", {stop}" for stop in event.stops)
        return (EVENT, clock(), s.EVENT_ROBOT_MODE, event.text, detail), 0
    return None


def topic_type(topic: str) -> s.MessageType:
    """The message type of a topic of a recording (any other topic is a camera's)."""
    # A UR's and an xArm's raw channels are registered when used.
    if topic in s.RAW_TOPICS or topic in s.RAW_UR_TOPICS or topic in s.RAW_XARM_TOPICS:
        return s.RAW_PACKET
    for name, message_type in DECODED_TOPICS:
        if name == topic:
            return message_type
    return s.COMPRESSED_IMAGE


class MessageConverter:
    """Queue items into messages for a sink; keeps the link state and extension state the
    statistics messages carry. `wall_ns` maps the link's monotonic time to wall-clock ns."""

    def __init__(self, profile: RobotProfile, wall_ns: Callable[[float], int], sink: Sink) -> None:
        self.profile = profile
        self.wall_ns = wall_ns
        self.sink = sink
        self._link_state = ""
        self._extension_active = False
        self._camera_names = profile.link.camera_names

    def convert(self, item: Item, dropped: int) -> None:
        """Turn one queued item into its message(s)."""
        kind, mono = item[0], item[1]
        if kind == SENT:
            self._sent(mono, item[2])
        elif kind == COMMAND:
            self._command(mono, item[2])
        elif kind == RECEIVED:
            self._received(mono, item[2])
        elif kind == TELEMETRY:
            self._telemetry(mono, item[2])
        elif kind == VIDEO:
            self._video(mono, item[2])
        elif kind == STATUS:
            self._status(mono, item[2])
        elif kind == STATS:
            self._stats(mono, item[2], dropped)
        elif kind == EVENT:
            self._event(mono, item[2], item[3], item[4])

    def _raw(self, send_ns: int, receive_ns: int, source: str, data: bytes) -> dict[str, Any]:
        return {
            "send_stamp": s.stamp(send_ns),
            "receive_stamp": s.stamp(receive_ns),
            "source": source,
            "data": data,
        }

    def _sent(self, mono: float, event: DatagramSent) -> None:
        topic = SENT_TOPICS.get(event.kind, s.RAW_OTHER)
        self.sink(mono, topic, self._raw(self.wall_ns(mono), 0, s.SOURCE_OCU, event.data))

    def _command(self, mono: float, command: Command) -> None:
        drive = self.profile.drive_channels
        if drive is not None:
            linear, turn = drive
            self.sink(
                mono,
                s.CMD_VEL,
                {
                    "linear": {"x": command.velocity(linear), "y": 0.0, "z": 0.0},
                    "angular": {"x": 0.0, "y": 0.0, "z": command.velocity(turn)},
                },
            )
        joints = [name for name in self.profile.channels if name not in (drive or ())]
        self.sink(
            mono,
            s.CMD_JOINTS,
            {
                "header": {"stamp": s.stamp(self.wall_ns(mono)), "frame_id": ""},
                "name": joints,
                "position": [],
                "velocity": [command.velocity(name) for name in joints],
                "effort": [],
            },
        )

    def _received(self, mono: float, event: DatagramReceived) -> None:
        # What the packet was and its own stamp come from the receiver, which decoded it.
        robot_ns = None if event.robot_time_s is None else round(event.robot_time_s * 1e9)
        self.sink(
            mono,
            RECEIVED_TOPICS.get(event.kind, s.RAW_OTHER),
            self._raw(robot_ns or 0, self.wall_ns(mono), s.SOURCE_ROBOT, event.data),
            publish_ns=robot_ns,
        )

    def _telemetry(self, mono: float, frame: TelemetryFrame) -> None:
        names: list[str] = []
        positions: list[float] = []
        velocities: list[float] = []
        efforts: list[float] = []
        for name, reading in frame.readings.items():
            if reading.angle_rad is None:
                continue
            names.append(name)
            positions.append(reading.angle_rad)
            velocities.append(reading.speed_rad_s)
            efforts.append(reading.current_a)
        self.sink(
            mono,
            s.JOINT_STATES,
            {
                "header": {"stamp": s.stamp(self.wall_ns(mono)), "frame_id": ""},
                "name": names,
                "position": positions,
                "velocity": velocities,
                "effort": efforts,
            },
            publish_ns=round(frame.packet.tick * 1e9 / self.profile.link.telemetry_tick_hz),
        )

    def camera_name(self, camera: int | None) -> str:
        """The name of a camera index; a vendor frame of unknown camera shows as camera 0."""
        index = 0 if camera is None else camera
        if 0 <= index < len(self._camera_names):
            return self._camera_names[index]
        return f"camera{index}"

    def _video(self, mono: float, frame: VideoFrame) -> None:
        name = self.camera_name(frame.camera)
        self.sink(
            mono,
            s.camera_topic(name),
            {
                "header": {"stamp": s.stamp(self.wall_ns(mono)), "frame_id": name},
                "format": "jpeg",
                "data": frame.jpeg,
            },
            publish_ns=None if frame.capture_time_us is None else frame.capture_time_us * 1000,
        )

    def _status(self, mono: float, frame: StatusFrame) -> None:
        headlight = frame.headlight_on
        self.sink(
            mono,
            s.ROBOT_STATUS,
            {
                "header": {"stamp": s.stamp(self.wall_ns(mono)), "frame_id": ""},
                "voltage_v": s.nan_if_none(frame.voltage_v),
                "charge_percent": s.nan_if_none(frame.charge_percent),
                "headlight": -1 if headlight is None else int(headlight),
                "roll_rad": s.nan_if_none(frame.roll_rad),
                "pitch_rad": s.nan_if_none(frame.pitch_rad),
            },
        )

    def _stats(self, mono: float, stats: LinkStats, dropped: int) -> None:
        self.sink(
            mono,
            s.LINK_STATS,
            {
                "stamp": s.stamp(self.wall_ns(mono)),
                "link_state": self._link_state,
                "sent": stats.sent,
                "received": stats.received,
                "telemetry": stats.telemetry,
                "video": stats.video,
                "malformed": stats.malformed,
                "foreign": stats.foreign,
                "send_errors": stats.send_errors,
                "rcp_rate_hz": stats.rcp_rate_hz,
                "telemetry_rate_hz": stats.telemetry_rate_hz,
                "video_rate_hz": stats.video_rate_hz,
                "loss_estimate": s.nan_if_none(stats.loss_estimate),
                "duplicates": stats.duplicates,
                "reordered": stats.reordered,
                "last_valid_age_s": s.nan_if_none(stats.last_valid_age_s),
                "send_rate_hz": stats.send_rate_hz,
                "estop_latched": stats.estop_latched,
                "extension_active": self._extension_active,
                "recorder_dropped": dropped,
                "delay_s": s.nan_if_none(stats.delay_s),
                "stale_telemetry": stats.stale_telemetry,
                "jitter_s": s.nan_if_none(stats.jitter_s),
                "scan_rate_hz": stats.scan_rate_hz,
                "frame_age_s": [s.nan_if_none(age) for age in stats.frame_age_s],
                "uplink_loss": s.nan_if_none(stats.uplink_loss),
            },
        )

    def _event(self, mono: float, kind: str, state: str, message: str) -> None:
        if kind == s.EVENT_LINK_STATE:
            self._link_state = state
        elif kind == s.EVENT_EXTENSION:
            self._extension_active = state == "active"
        self.sink(
            mono,
            s.EVENTS,
            {
                "stamp": s.stamp(self.wall_ns(mono)),
                "kind": kind,
                "state": state,
                "message": message,
            },
        )
