"""One recording file: the conversion of link events into ROS 2 messages and their writing.

Used by ocu.record.recorder on its writer thread. Times: the link's monotonic seconds are
mapped to wall-clock nanoseconds through one (monotonic, wall) pair read when the file is
opened; log_time is the local stamp (receive time, or send time for what the OCU sent),
publish_time the packet's own stamp where it carries one (robot clock), else log_time.
"""

from __future__ import annotations

import contextlib
import heapq
import io
import json
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType, Writer

from ocu import records as r
from ocu.profile import RobotProfile
from ocu.record import schemas as s
from ocu.records import (
    Command,
    DatagramReceived,
    DatagramSent,
    LinkStats,
    StatusFrame,
    TelemetryFrame,
    VideoFrame,
)

# What the recorder queues: (kind, monotonic time, payload...). The kinds:
SENT = 0
RECEIVED = 1
TELEMETRY = 2
VIDEO = 3
STATUS = 4
STATS = 5
EVENT = 6
COMMAND = 7

# The raw channel of each kind of datagram (ocu.records).
SENT_TOPICS = {r.RCP: s.RAW_RCP, r.HELLO: s.RAW_HELLO, r.UR_SCRIPT: s.RAW_UR_SCRIPT}
RECEIVED_TOPICS = {
    r.TELEMETRY: s.RAW_TELEMETRY,
    r.VIDEO: s.RAW_VIDEO,
    r.VIDEO_FRAGMENT: s.RAW_VIDEO_FRAGMENT,
    r.STATUS: s.RAW_STATUS,
    r.SCAN: s.RAW_SCAN,
    r.UR_PRIMARY: s.RAW_UR_PRIMARY,
    r.UR_SECONDARY: s.RAW_UR_SECONDARY,
    r.UR_REALTIME: s.RAW_UR_REALTIME,
}

Item = tuple[Any, ...]


def clock_pair(clock: Callable[[], float]) -> tuple[float, int]:
    # The wall time read between two monotonic reads; the tightest of a few tries.
    best: tuple[float, float, int] | None = None
    for _ in range(3):
        before = clock()
        wall = time.time_ns()
        after = clock()
        if best is None or after - before < best[1] - best[0]:
            best = (before, after, wall)
    assert best is not None
    return (best[0] + best[1]) / 2.0, best[2]


class RecordingFile:
    """One open MCAP file and the conversions into it (the writer thread's, after __init__).

    Opening writes the header, the metadata, the profile and every known channel and hands
    them to the operating system, so an unusable target fails here, in start().
    """

    def __init__(
        self,
        profile: RobotProfile,
        path: Path,
        *,
        chunk_bytes: int,
        flush_period_s: float,
        compression: CompressionType,
        clock: Callable[[], float],
        note: str = "",
    ) -> None:
        mono0, wall0_ns = clock_pair(clock)
        self.path = path
        self.profile = profile
        self.chunk_bytes = chunk_bytes
        self.flush_period_s = flush_period_s
        self.mono0 = mono0
        self.wall0_ns = wall0_ns
        self.messages = 0
        self._pending_since_flush = 0
        self._heap: list[tuple[float, int, int, bytes, int]] = []
        self._sequence = 0
        self._last_flush = mono0
        self._closed = False
        self._link_state = ""
        self._extension_active = False
        self._camera_names = profile.link.camera_names
        self._encoders = {t.name: s.make_encoder(t) for t in s.MESSAGE_TYPES}
        self._file: io.BufferedWriter = open(path, "wb")  # noqa: SIM115 - closed in close()
        try:
            self._writer = Writer(self._file, chunk_size=self.chunk_bytes, compression=compression)
            self._writer.start(profile=s.PROFILE, library=_library())
            self._writer.add_metadata(s.METADATA_NAME, self._metadata(note))
            self._attach_profile()
            self._schemas = {
                t.name: self._writer.register_schema(
                    t.name, s.SCHEMA_ENCODING, t.definition.encode()
                )
                for t in s.MESSAGE_TYPES
            }
            self._channels: dict[str, tuple[int, str]] = {}
            for topic in s.RAW_TOPICS:
                self._channel(topic, s.RAW_PACKET.name)
            for topic, type_name in (
                (s.CMD_VEL, s.TWIST.name),
                (s.CMD_JOINTS, s.JOINT_STATE.name),
                (s.JOINT_STATES, s.JOINT_STATE.name),
                (s.LINK_STATS, s.LINK_STATS_TYPE.name),
                (s.EVENTS, s.EVENT.name),
                (s.ROBOT_STATUS, s.ROBOT_STATUS_TYPE.name),
            ):
                self._channel(topic, type_name)
            for index, name in enumerate(self._camera_names):
                self._channel(s.camera_topic(name), s.COMPRESSED_IMAGE.name, camera=index)
            # Fail now, with the operator still at the button, if the disk takes nothing.
            self._file.flush()
        except BaseException:
            self._file.close()
            raise

    def _metadata(self, note: str) -> dict[str, str]:
        link = self.profile.link
        types = link.frame_types
        ext = self.profile.extension
        return {
            "format_version": s.FORMAT_VERSION,
            "ocu_version": _ocu_version(),
            "profile_name": self.profile.name,
            "camera_names": json.dumps(list(self._camera_names)),
            "frame_types": json.dumps(
                {"rcp": types.rcp, "telemetry": types.telemetry, "video": types.video}
                | (
                    {
                        "hello": ext.frame_types.hello,
                        "video_fragment": ext.frame_types.video_fragment,
                        "status": ext.frame_types.status,
                    }
                    if ext is not None
                    else {}
                )
            ),
            "telemetry_tick_hz": repr(link.telemetry_tick_hz),
            "clock": "log_time = wall_anchor_ns + (monotonic - monotonic_anchor) in ns",
            "wall_anchor_ns": str(self.wall0_ns),
            "monotonic_anchor_ns": str(round(self.mono0 * 1e9)),
            "note": note,
        }

    def _attach_profile(self) -> None:
        try:
            text = Path(self.profile.source).read_bytes()
        except OSError:
            return  # a profile built in memory: replay then uses the one it is given
        self._writer.add_attachment(
            create_time=self.wall0_ns,
            log_time=self.wall0_ns,
            name=s.PROFILE_ATTACHMENT,
            media_type="application/toml",
            data=text,
        )

    def _channel(self, topic: str, type_name: str, camera: int | None = None) -> tuple[int, str]:
        known = self._channels.get(topic)
        if known is not None:
            return known
        metadata = {} if camera is None else {"camera_index": str(camera)}
        channel_id = self._writer.register_channel(
            topic, s.MESSAGE_ENCODING, self._schemas[type_name], metadata
        )
        self._channels[topic] = (channel_id, type_name)
        return channel_id, type_name

    # ---- conversions -----------------------------------------------------------------------

    def wall_ns(self, mono: float) -> int:
        """Wall-clock nanoseconds of a monotonic time."""
        return self.wall0_ns + round((mono - self.mono0) * 1e9)

    def _add(self, mono: float, topic: str, message: Any, publish_ns: int | None = None) -> None:
        channel_id, type_name = self._channels.get(topic) or self._late_channel(topic)
        data = self._encoders[type_name](message)
        self._sequence += 1
        log_ns = self.wall_ns(mono)
        heapq.heappush(
            self._heap,
            (mono, self._sequence, channel_id, data, log_ns if publish_ns is None else publish_ns),
        )

    def _late_channel(self, topic: str) -> tuple[int, str]:
        # A UR's raw channels, and a camera the profile does not name: registered when used.
        if topic in s.RAW_UR_TOPICS:
            return self._channel(topic, s.RAW_PACKET.name)
        return self._channel(topic, s.COMPRESSED_IMAGE.name)

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
        self._add(mono, topic, self._raw(self.wall_ns(mono), 0, s.SOURCE_OCU, event.data))

    def _command(self, mono: float, command: Command) -> None:
        drive = self.profile.drive_channels
        if drive is not None:
            linear, turn = drive
            self._add(
                mono,
                s.CMD_VEL,
                {
                    "linear": {"x": command.velocity(linear), "y": 0.0, "z": 0.0},
                    "angular": {"x": 0.0, "y": 0.0, "z": command.velocity(turn)},
                },
            )
        joints = [name for name in self.profile.channels if name not in (drive or ())]
        self._add(
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
        self._add(
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
        self._add(
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
        self._add(
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
        self._add(
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
        self._add(
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
        self._add(
            mono,
            s.EVENTS,
            {
                "stamp": s.stamp(self.wall_ns(mono)),
                "kind": kind,
                "state": state,
                "message": message,
            },
        )

    # ---- writing ---------------------------------------------------------------------------

    def write_due(self, before: float | None) -> None:
        """Write the held messages older than `before` (all when None), in time order."""
        heap = self._heap
        writer = self._writer
        while heap and (before is None or heap[0][0] <= before):
            mono, sequence, channel_id, data, publish_ns = heapq.heappop(heap)
            writer.add_message(
                channel_id=channel_id,
                log_time=self.wall_ns(mono),
                data=data,
                publish_time=publish_ns,
                sequence=sequence & 0xFFFFFFFF,
            )
            self.messages += 1
            self._pending_since_flush += 1
        # mcap wrote any chunk it closed into the file object: pass it on to the kernel now.
        self._file.flush()

    def flush_if_due(self, now: float) -> None:
        """Close the open chunk once it is flush_period_s old, so a crash loses little."""
        if now - self._last_flush < self.flush_period_s:
            return
        self._last_flush = now
        if self._pending_since_flush:
            self._writer.flush()  # type: ignore[no-untyped-call]
            self._pending_since_flush = 0

    def finish(self) -> None:
        """Write everything held, the summary and the footer."""
        self.write_due(None)
        self._writer.finish()  # type: ignore[no-untyped-call]
        self._file.flush()
        self.close()

    def file_bytes(self) -> int:
        """Bytes in the file so far."""
        try:
            return os.stat(self.path).st_size
        except OSError:
            return 0

    def close(self) -> None:
        """Close the file; errors are reported by the writes before, not here."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(OSError):
            self._file.close()


def _ocu_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ocu")
    except PackageNotFoundError:
        return "unknown"


def _library() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        mcap_version = version("mcap")
    except PackageNotFoundError:
        mcap_version = "unknown"
    return f"ocu {_ocu_version()} (mcap-python {mcap_version})"
