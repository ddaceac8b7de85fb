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

from ocu.profile import RobotProfile
from ocu.record import schemas as s
from ocu.record.convert import DECODED_TOPICS, Item, MessageConverter, topic_type


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
        self._camera_names = profile.link.camera_names
        self._converter = MessageConverter(profile, self.wall_ns, self._add)
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
            for topic, message_type in DECODED_TOPICS:
                self._channel(topic, message_type.name)
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

    def convert(self, item: Item, dropped: int) -> None:
        """Turn one queued item into its message(s), held for writing in time order."""
        self._converter.convert(item, dropped)

    def camera_name(self, camera: int | None) -> str:
        """The name of a camera index (see MessageConverter.camera_name)."""
        return self._converter.camera_name(camera)

    def _add(
        self, mono: float, topic: str, message: dict[str, Any], publish_ns: int | None = None
    ) -> None:
        channel_id, type_name = self._channels.get(topic) or self._channel(
            topic, topic_type(topic).name
        )
        data = self._encoders[type_name](message)
        self._sequence += 1
        log_ns = self.wall_ns(mono)
        heapq.heappush(
            self._heap,
            (mono, self._sequence, channel_id, data, log_ns if publish_ns is None else publish_ns),
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
