"""`ocu inspect FILE.mcap`: what a recording holds and how the link did, by hand-checkable rules.

The figures are those seed 002 section 7 computes by hand from its logs: per channel counts
and rates, and packet loss per direction as the share of packets sent that never arrived.
Robot -> OCU loss comes from gaps in the telemetry tick counter and from gaps in the
extension's per-camera video sequence numbers; OCU -> robot loss cannot be seen from the
OCU's side (the robot acknowledges nothing) and is reported as such. A file cut short is read
up to its last complete chunk and said to be truncated; zeros where records should be are
reported with their byte offset and not read (chunks after them are found through the file's
chunk index when it has one).

The telemetry period is estimated from the whole recording with the same rule as the live
link (ocu.link.stats.tick_loss): the median of the tick steps near the shortest quarter.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import statistics
import sys
import time
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

from ocu.link.receiver import Receiver
from ocu.link.stats import UplinkLossEstimator, tick_loss
from ocu.link.ur_wire import UrDecoder
from ocu.profile import ProfileError, RobotProfile, load_profile
from ocu.protocol.extended import StatusPacket
from ocu.protocol.ur import (
    UrProtocolError,
    VersionMessage,
    decode_primary,
    parse_script_line,
    realtime_size,
)
from ocu.protocol.xarm import Cmd, Direction, FrameReader, XarmProtocolError, decode_servo_move
from ocu.record import schemas as s
from ocu.record.errors import RecordingError
from ocu.record.reader import Recording
from ocu.records import TELEMETRY, DatagramReceived, LinkEvent, StatusFrame, VideoFrame

SEQUENCE_MODULO = 2**32


@dataclass
class ChannelSummary:
    """Messages on one topic."""

    topic: str
    messages: int = 0
    bytes: int = 0
    first_ns: int = 0
    last_ns: int = 0
    longest_gap_s: float = 0.0

    @property
    def rate_hz(self) -> float:
        """Mean rate between the first and the last message."""
        span_s = (self.last_ns - self.first_ns) / 1e9
        return (self.messages - 1) / span_s if self.messages > 1 and span_s > 0 else 0.0

    def add(self, log_time_ns: int, size: int) -> None:
        """Count one message."""
        if self.messages:
            self.longest_gap_s = max(self.longest_gap_s, (log_time_ns - self.last_ns) / 1e9)
        else:
            self.first_ns = log_time_ns
        self.messages += 1
        self.bytes += size
        self.last_ns = log_time_ns


@dataclass
class CameraSummary:
    """Frames of one camera: delivered, rate, and lost (extension video only)."""

    name: str
    frames: int = 0
    fps: float = 0.0
    lost: int | None = None

    @property
    def loss(self) -> float | None:
        """Share of the frames sent that never completed."""
        if self.lost is None or self.frames + self.lost == 0:
            return None
        return self.lost / (self.frames + self.lost)


@dataclass
class Summary:
    """Everything `ocu inspect` prints."""

    path: str
    size_bytes: int
    truncated: bool
    corrupt_chunks: int
    damaged_at: int | None
    recovered_chunks: int
    profile_name: str
    start_wall_s: float
    duration_s: float
    channels: list[ChannelSummary] = field(default_factory=list)
    rcp_sent: int = 0
    rcp_rate_hz: float = 0.0
    rcp_longest_gap_s: float = 0.0
    robot_watchdog_s: float = 0.0
    telemetry_received: int = 0
    telemetry_lost: int = 0
    telemetry_duplicates: int = 0
    telemetry_reordered: int = 0
    telemetry_rate_hz: float = 0.0
    telemetry_longest_gap_s: float = 0.0
    cameras: list[CameraSummary] = field(default_factory=list)
    events: list[tuple[float, str, str, str]] = field(default_factory=list)
    estops: int = 0
    malformed: int | None = None
    recorder_dropped: int | None = None
    # From the link statistics channel: the measured round trip and its jitter (ms).
    round_trip_median_ms: float | None = None
    round_trip_max_ms: float | None = None
    jitter_median_ms: float | None = None
    # Commands the robot never applied, from its echo (status version 3); None: no echo.
    rcp_loss: float | None = None
    # A UR arm's recording: its commands are URScript lines, its telemetry realtime packets.
    ur: bool = False
    stopj_sent: int = 0
    controller_stops: int = 0
    # An xArm's recording: frames written to the board and read from it (ocu.link.xarm).
    xarm: bool = False
    xarm_moves: int = 0
    xarm_stop_moves: int = 0
    xarm_reads: int = 0
    xarm_frames_received: int = 0
    xarm_bad_frames: int = 0
    xarm_skipped_bytes: int = 0

    @property
    def telemetry_loss(self) -> float | None:
        """Share of telemetry packets sent by the robot that never arrived."""
        total = self.telemetry_received + self.telemetry_lost
        return self.telemetry_lost / total if total else None


def summarize(recording: Recording, profile: RobotProfile) -> Summary:
    """Read the whole recording once and compute the summary."""
    summary = Summary(
        path=str(recording.path),
        size_bytes=recording.size_bytes,
        truncated=recording.truncated,
        corrupt_chunks=0,
        damaged_at=recording.damaged_at,
        recovered_chunks=recording.recovered_chunks,
        profile_name=recording.metadata.get("profile_name", profile.name),
        start_wall_s=recording.start_ns / 1e9,
        duration_s=recording.duration_s,
        robot_watchdog_s=profile.link.robot_watchdog_s,
    )
    channels: dict[str, ChannelSummary] = {}
    ticks: list[int] = []
    completed: dict[int, int] = defaultdict(int)
    sequences: dict[int, tuple[int, int]] = {}
    tick_hz = profile.link.telemetry_tick_hz

    # The robot's echo of the sequenced RCPs over the whole recording (a restart starts over).
    uplink = UplinkLossEstimator(window_s=math.inf)

    def count(event: LinkEvent) -> None:
        # Every telemetry datagram counts for the loss, also the late and repeated ones.
        if isinstance(event, DatagramReceived) and event.kind == TELEMETRY:
            assert event.robot_time_s is not None
            ticks.append(round(event.robot_time_s * tick_hz))
        elif isinstance(event, StatusFrame) and isinstance(event.packet, StatusPacket):
            echo = event.packet
            if echo.rcp_sequence is not None and echo.rcp_received is not None:
                uplink.add(echo.rcp_sequence, echo.rcp_received, event.received_at)
        elif isinstance(event, VideoFrame) and event.camera is not None:
            if event.sequence is None:
                return
            first, last = sequences.get(event.camera, (event.sequence, event.sequence))
            if (event.sequence - last) % SEQUENCE_MODULO < SEQUENCE_MODULO // 2:
                last = event.sequence
            sequences[event.camera] = (first, last)
            completed[event.camera] += 1

    # The live link's own receiver decodes the recorded datagrams, on the recording's clock;
    # a UR's packets go through the UR link's decoder.
    receiver = Receiver(profile, count, extension=True)
    ur = UrFigures(tick_hz)
    xarm = XarmFigures(recording.xarm() is not None)
    last_stats = None
    round_trips: list[float] = []
    jitters: list[float] = []
    start_ns = recording.start_ns
    for message in recording.messages():
        topic = message.topic
        channel = channels.get(topic)
        if channel is None:
            channel = channels[topic] = ChannelSummary(topic)
        channel.add(message.log_time_ns, len(message.data))
        if xarm.active and topic in (*s.RAW_XARM_TOPICS, s.RAW_OTHER):
            raw = recording.decode(message)
            xarm.add(topic, bytes(raw.data), raw.source)
        elif topic in s.RAW_TOPICS:
            raw = recording.decode(message)
            if raw.source == s.SOURCE_ROBOT:
                at = message.log_time_ns / 1e9
                receiver.received(bytes(raw.data), at, at)
        elif topic in s.RAW_UR_TOPICS:
            ur.add(topic, bytes(recording.decode(message).data), ticks)
        elif topic == s.LINK_STATS:
            last_stats = recording.decode(message)
            round_trips.append(float(getattr(last_stats, "delay_s", math.nan)) * 1e3)
            jitters.append(float(getattr(last_stats, "jitter_s", math.nan)) * 1e3)
        elif topic == s.EVENTS:
            event = recording.decode(message)
            offset_s = (message.log_time_ns - start_ns) / 1e9
            summary.events.append((offset_s, event.kind, event.state, event.message))
            if event.kind == s.EVENT_SAFETY and event.message.startswith("EMERGENCY STOP"):
                summary.estops += 1
            elif event.kind == s.EVENT_ROBOT_MODE and "STOP" in event.state:
                summary.controller_stops += 1
    summary.corrupt_chunks = recording.corrupt_chunks
    summary.channels = sorted(channels.values(), key=lambda c: c.topic)

    summary.ur = recording.ur_arm() is not None
    summary.xarm = xarm.active
    if xarm.active:
        summary.xarm_moves = xarm.moves
        summary.xarm_stop_moves = xarm.stop_moves
        summary.xarm_reads = xarm.reads
        summary.xarm_frames_received = xarm.reader.frames
        summary.xarm_bad_frames = xarm.reader.bad_frames
        summary.xarm_skipped_bytes = xarm.reader.skipped_bytes
    summary.stopj_sent = ur.stopj
    rcp = channels.get(
        s.RAW_UR_SCRIPT if summary.ur else s.RAW_XARM_TO_BOARD if summary.xarm else s.RAW_RCP
    )
    if rcp is not None:
        summary.rcp_sent = rcp.messages
        summary.rcp_rate_hz = rcp.rate_hz
        summary.rcp_longest_gap_s = rcp.longest_gap_s
    raw_telemetry = channels.get(
        s.RAW_UR_REALTIME
        if summary.ur
        else s.RAW_XARM_FROM_BOARD
        if summary.xarm
        else s.RAW_TELEMETRY
    )
    if raw_telemetry is not None:
        summary.telemetry_rate_hz = raw_telemetry.rate_hz
        summary.telemetry_longest_gap_s = raw_telemetry.longest_gap_s
    loss = tick_loss(ticks)
    summary.telemetry_duplicates = loss.duplicates
    summary.telemetry_reordered = loss.reordered
    summary.telemetry_received = loss.received
    summary.telemetry_lost = loss.lost

    names = profile.link.camera_names
    for index, name in enumerate(names):
        images = channels.get(s.camera_topic(name))
        camera = CameraSummary(name)
        if index in sequences:
            first, last = sequences[index]
            sent = (last - first) % SEQUENCE_MODULO + 1
            camera.frames = completed[index]
            camera.lost = max(sent - camera.frames, 0)
        elif images is not None:
            camera.frames = images.messages
        if images is not None:
            camera.fps = images.rate_hz
        if camera.frames or camera.lost:
            summary.cameras.append(camera)
    if last_stats is not None:
        summary.malformed = int(last_stats.malformed)
        summary.recorder_dropped = int(last_stats.recorder_dropped)
    summary.rcp_loss = uplink.loss(recording.end_ns / 1e9)
    known = [value for value in round_trips if math.isfinite(value)]
    if known:
        summary.round_trip_median_ms = statistics.median(known)
        summary.round_trip_max_ms = max(known)
    known = [value for value in jitters if math.isfinite(value)]
    if known:
        summary.jitter_median_ms = statistics.median(known)
    return summary


class UrFigures:
    """A UR's raw packets counted: realtime controller times as ticks, stopj lines sent."""

    def __init__(self, tick_hz: float) -> None:
        self.tick_hz = tick_hz
        self.decoder = UrDecoder()
        self.stopj = 0

    def add(self, topic: str, data: bytes, ticks: list[int]) -> None:
        """One recorded packet or script line."""
        if topic == s.RAW_UR_REALTIME:
            for state in self.decoder.realtime(data):
                if math.isfinite(state.time_s):
                    ticks.append(round(state.time_s * self.tick_hz))
        elif topic == s.RAW_UR_SCRIPT:
            # A line that is not the link's is counted as sent all the same.
            with contextlib.suppress(UnicodeDecodeError, UrProtocolError):
                self.stopj += parse_script_line(data.decode("ascii")).name == "stopj"
        elif topic == s.RAW_UR_PRIMARY:
            with contextlib.suppress(UrProtocolError):
                decoded = decode_primary(data)
                if isinstance(decoded, VersionMessage):
                    self.decoder = UrDecoder(realtime_size(decoded.version))


class XarmFigures:
    """An xArm's frames counted: the board's replies through a frame reader as the live
    link's (its bad frames and skipped bytes), the moves and reads the OCU wrote."""

    def __init__(self, active: bool) -> None:
        self.reader = FrameReader(Direction.FROM_BOARD)
        self.active = active
        self.moves = 0
        self.stop_moves = 0
        self.reads = 0

    def add(self, topic: str, data: bytes, source: str) -> None:
        """One recorded frame, or bytes the live reader skipped (/raw/other, the board's)."""
        if topic == s.RAW_XARM_TO_BOARD:
            for frame in FrameReader(Direction.TO_BOARD).feed(data):
                if frame.command == Cmd.SERVO_MOVE:
                    self.moves += 1
                    with contextlib.suppress(XarmProtocolError):
                        self.stop_moves += decode_servo_move(frame.parameters).duration_ms == 0
                elif frame.command == Cmd.MULT_SERVO_POS_READ:
                    self.reads += 1
        elif source == s.SOURCE_ROBOT:
            self.reader.feed(data)


def _size(count: int) -> str:
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if count >= scale:
            return f"{count / scale:.1f} {unit}"
    return f"{count} B"


def _percent(value: float | None) -> str:
    return "n/a" if value is None else f"{value * 100:.2f} %"


def render(summary: Summary) -> str:
    """The summary as text."""
    state = (
        "TRUNCATED: no summary or footer (recorder killed?); read up to the last complete chunk"
        if summary.truncated
        else "complete"
    )
    started = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(summary.start_wall_s))
    lines = [
        f"{summary.path}  ({_size(summary.size_bytes)}, {state})",
        f"recorded {started} (local), duration {summary.duration_s:.1f} s, "
        f"profile {summary.profile_name}",
    ]
    if summary.damaged_at is not None:
        found = (
            f"{summary.recovered_chunks} later chunk(s) found through the chunk index"
            if summary.recovered_chunks
            else f"the {_size(summary.size_bytes - summary.damaged_at)} after it not read"
        )
        lines.append(f"WARNING: zeros instead of records at byte {summary.damaged_at}: {found}")
    if summary.corrupt_chunks:
        lines.append(f"WARNING: {summary.corrupt_chunks} damaged chunk(s) skipped")
    lines += ["", f"{'channel':<34} {'messages':>9} {'rate':>10} {'bytes':>10}"]
    for channel in summary.channels:
        lines.append(
            f"{channel.topic:<34} {channel.messages:>9} {channel.rate_hz:>8.1f}/s "
            f"{_size(channel.bytes):>10}"
        )
    rcp_drop = (
        "drop: not observable from the OCU (the robot acknowledges nothing)"
        if summary.rcp_loss is None
        else f"drop {_percent(summary.rcp_loss)} (the robot's echo of its sequenced RCPs)"
    )
    sent = (
        f"{summary.rcp_sent} URScript lines sent ({summary.stopj_sent} stopj)"
        if summary.ur
        else f"{summary.rcp_sent} frames written"
        if summary.xarm
        else f"{summary.rcp_sent} RCPs sent"
    )
    watchdog = "speedj t" if summary.ur else "robot watchdog"
    lines += [
        "",
        "link (packet drop = packets sent that never arrived, as in seed 002 section 7)",
        f"  OCU -> robot  {sent}, {summary.rcp_rate_hz:.1f}/s, "
        f"longest gap {summary.rcp_longest_gap_s:.2f} s "
        f"({watchdog} {summary.robot_watchdog_s:.2f} s); "
        + ("drop n/a (TCP: delivered, or the connection is lost)" if summary.ur else rcp_drop),
        f"  robot -> OCU  {'realtime packets' if summary.ur else 'telemetry'} "
        f"{summary.telemetry_received} received, "
        f"{summary.telemetry_lost} lost: drop {_percent(summary.telemetry_loss)}; "
        f"{summary.telemetry_rate_hz:.1f}/s, longest gap {summary.telemetry_longest_gap_s:.2f} s, "
        f"{summary.telemetry_duplicates} duplicates, {summary.telemetry_reordered} reordered",
    ]
    for camera in summary.cameras:
        lost = (
            "drop n/a (vendor video has no sequence numbers)"
            if camera.lost is None
            else f"{camera.lost} lost: drop {_percent(camera.loss)}"
        )
        lines.append(
            f"  video {camera.name:<7} {camera.frames} frames, {camera.fps:.1f} fps, {lost}"
        )
    if summary.malformed is not None:
        lines.append(
            f"  malformed datagrams {summary.malformed}, "
            f"recorder dropped {summary.recorder_dropped} message(s)"
        )
    if summary.round_trip_median_ms is not None:
        jitter = summary.jitter_median_ms
        lines.append(
            f"  round trip    median {summary.round_trip_median_ms:.0f} ms, "
            f"max {summary.round_trip_max_ms:.0f} ms; jitter median "
            f"{'n/a' if jitter is None else f'{jitter:.0f} ms'} (link statistics)"
        )
    if summary.xarm:
        lines.append(
            f"  xArm board    {summary.xarm_moves} moves sent ({summary.xarm_stop_moves} stop "
            f"moves), {summary.xarm_reads} position reads; {summary.xarm_frames_received} "
            f"frames received, {summary.xarm_bad_frames} bad frame(s) "
            f"({summary.xarm_skipped_bytes} bytes skipped)"
        )
    stops = f", {summary.controller_stops} controller stop(s)" if summary.ur else ""
    lines += ["", f"events ({summary.estops} emergency stop(s){stops})"]
    for offset_s, kind, event_state, message in summary.events:
        detail = f"{event_state}: {message}" if event_state else message
        lines.append(f"  {offset_s:+9.3f} s  {kind:<10} {detail}")
    return "\n".join(lines)


def as_json(summary: Summary) -> str:
    """The summary as JSON, derived figures included."""
    data = asdict(summary)
    data["telemetry_loss"] = summary.telemetry_loss
    for channel, source in zip(data["channels"], summary.channels, strict=True):
        channel["rate_hz"] = source.rate_hz
    for camera, source_camera in zip(data["cameras"], summary.cameras, strict=True):
        camera["loss"] = source_camera.loss
    return json.dumps(data, indent=2)


def build_parser() -> argparse.ArgumentParser:
    """Command-line options of `ocu inspect`."""
    parser = argparse.ArgumentParser(
        prog="ocu inspect",
        description="Summarise an ocu recording: duration, per channel counts, rates and "
        "bytes, link loss per direction, video rate per camera, e-stops and other events.",
    )
    parser.add_argument("file", help="an MCAP file written by `ocu --record` or the Record button")
    parser.add_argument(
        "--profile", metavar="FILE", help="robot profile when the recording holds none"
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of `ocu inspect`; 0 on success, 1 if the file cannot be read."""
    args = build_parser().parse_args(argv)
    try:
        fallback = load_profile(args.profile)
    except ProfileError as err:
        print(f"ocu inspect: {err}", file=sys.stderr)
        return 1
    try:
        with Recording(args.file) as recording:
            summary = summarize(recording, recording.profile(fallback))
    except RecordingError as err:
        print(f"ocu inspect: {err}", file=sys.stderr)
        return 1
    print(as_json(summary) if args.json else render(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
