"""Open an MCAP recording for replay and inspection, finished or cut short.

A finished file ends with a summary and a footer; a file whose recorder was killed ends
somewhere in the middle of a chunk. Both open the same way: the record framing (opcode and
length, MCAP's outer layer) is walked once without reading chunk contents, which indexes the
complete chunks by time and finds the metadata and the recorded profile; a record that runs
past the end of the file marks the file as truncated and everything before it stays usable.
Zeros where a record should start (opcode 0 is no record: a file extended or preallocated, a
region a crash left unwritten) end the walk at once instead of being stepped through nine
bytes at a time; chunks after them are still found when the file ends with its footer, through
the summary's chunk index.
Chunks are then read one at a time on demand with the mcap package's record readers, so
memory stays bounded by one chunk whatever the length of the recording.
"""

from __future__ import annotations

import io
import logging
import struct
import tomllib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, BinaryIO

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    Footer,
    Header,
    Message,
    Metadata,
    MetadataIndex,
    Schema,
)
from mcap.stream_reader import breakup_chunk
from mcap_ros2.decoder import DecoderFactory

from ocu.profile import ProfileError, RobotProfile, parse_profile
from ocu.profile.ur import UrArmProfile, load_ur_profile, parse_ur_profile, shipped_ur_profiles
from ocu.profile.ur_robot import ur_robot_profile
from ocu.profile.xarm import (
    XarmProfile,
    load_xarm_profile,
    parse_xarm_profile,
    shipped_xarm_profiles,
)
from ocu.profile.xarm_robot import xarm_robot_profile
from ocu.record import schemas as s
from ocu.record.errors import RecordingError

log = logging.getLogger("ocu.record")

MAGIC = b"\x89MCAP0\r\n"
# How many topics the refusal of a foreign file names.
FOREIGN_TOPICS_SHOWN = 8
_RECORD_HEAD = struct.Struct("<BQ")
_CHUNK_TIMES = struct.Struct("<QQ")
# The footer record's body: summary start, summary offset start, summary CRC.
_FOOTER_BODY_BYTES = 20
_TAIL_BYTES = _RECORD_HEAD.size + _FOOTER_BODY_BYTES + len(MAGIC)


@dataclass(frozen=True)
class ChunkInfo:
    """Where one complete chunk lies and the log times it covers."""

    offset: int
    length: int
    start_ns: int
    end_ns: int


@dataclass(frozen=True)
class RecordedMessage:
    """One message as stored: topic, times (ns) and CDR bytes."""

    topic: str
    log_time_ns: int
    publish_time_ns: int
    data: bytes
    schema_id: int


class Recording:
    """A recording opened for reading; close() it (or use `with`)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            self._file: BinaryIO = open(self.path, "rb")  # noqa: SIM115 - closed in close()
        except OSError as err:
            raise RecordingError(f"cannot open {self.path}: {err.strerror or err}") from err
        try:
            self.size_bytes = self.path.stat().st_size
            self.library = ""
            self.truncated = True
            self.metadata: dict[str, str] = {}
            self.profile_toml: bytes | None = None
            self.chunks: list[ChunkInfo] = []
            self.corrupt_chunks = 0
            # Where bytes that are no record (zeros) begin, if anywhere; chunks after them
            # that the summary's chunk index located.
            self.damaged_at: int | None = None
            self.recovered_chunks = 0
            self.channels: dict[int, Channel] = {}
            self.schemas: dict[int, Schema] = {}
            self._decoders: dict[int, Callable[[bytes], Any]] = {}
            self._factory = DecoderFactory()
            self._index()
            if self.chunks and not self.channels:
                # A file cut short has no summary: its channels sit in the first chunk.
                self.read_chunk(0)
            self._check_ours()
        except BaseException:
            self._file.close()
            raise

    # ---- opening ---------------------------------------------------------------------------

    def _index(self) -> None:
        f = self._file
        if f.read(len(MAGIC)) != MAGIC:
            raise RecordingError(f"{self.path} is not an MCAP file")
        offset = len(MAGIC)
        while offset + _RECORD_HEAD.size <= self.size_bytes:
            f.seek(offset)
            opcode, length = _RECORD_HEAD.unpack(f.read(_RECORD_HEAD.size))
            if opcode == 0:
                self.damaged_at = offset
                log.warning("%s: no MCAP record at byte %d (zeros)", self.path, offset)
                self._recover_from_summary(offset)
                break
            body_at = offset + _RECORD_HEAD.size
            end = body_at + length
            if end > self.size_bytes:
                break  # a record cut short by a killed writer
            if opcode == Opcode.CHUNK:
                start_ns, end_ns = _CHUNK_TIMES.unpack(f.read(_CHUNK_TIMES.size))
                self.chunks.append(ChunkInfo(offset, length, start_ns, end_ns))
            elif opcode in (
                Opcode.HEADER,
                Opcode.METADATA,
                Opcode.ATTACHMENT,
                Opcode.CHANNEL,
                Opcode.SCHEMA,
            ):
                self._top_level(opcode, self._body(body_at, length))
            elif opcode == Opcode.FOOTER:
                self.truncated = False
                break
            offset = end

    def _recover_from_summary(self, damaged_at: int) -> None:
        """Index what lies past the damage through the summary, if the file ends with one."""
        f = self._file
        footer_at = self.size_bytes - _TAIL_BYTES
        if footer_at <= damaged_at:
            return
        f.seek(footer_at)
        tail = f.read(_TAIL_BYTES)
        opcode, length = _RECORD_HEAD.unpack_from(tail)
        if tail[-len(MAGIC) :] != MAGIC or opcode != Opcode.FOOTER or length != _FOOTER_BODY_BYTES:
            return
        footer = Footer.read(ReadDataStream(io.BytesIO(tail[_RECORD_HEAD.size : -len(MAGIC)])))
        offset = footer.summary_start
        if not damaged_at < offset < footer_at:
            return
        later: list[int] = []  # metadata and attachments past the damage
        while offset + _RECORD_HEAD.size <= footer_at:
            f.seek(offset)
            opcode, length = _RECORD_HEAD.unpack(f.read(_RECORD_HEAD.size))
            body_at = offset + _RECORD_HEAD.size
            if opcode == 0 or body_at + length > footer_at:
                return  # the summary is damaged too
            try:
                if opcode == Opcode.CHUNK_INDEX:
                    self._recover_chunk(ChunkIndex.read(self._body(body_at, length)), damaged_at)
                elif opcode in (Opcode.CHANNEL, Opcode.SCHEMA):
                    self._top_level(opcode, self._body(body_at, length))
                elif opcode == Opcode.METADATA_INDEX:
                    later.append(MetadataIndex.read(self._body(body_at, length)).offset)
                elif opcode == Opcode.ATTACHMENT_INDEX:
                    later.append(AttachmentIndex.read(self._body(body_at, length)).offset)
            except (McapError, struct.error, UnicodeDecodeError) as err:
                log.warning("%s: skipped a damaged summary record: %s", self.path, err)
            offset = body_at + length
        self.truncated = False
        for record_at in later:
            if damaged_at < record_at < footer_at:
                f.seek(record_at)
                opcode, length = _RECORD_HEAD.unpack(f.read(_RECORD_HEAD.size))
                if opcode in (Opcode.METADATA, Opcode.ATTACHMENT):
                    body_at = record_at + _RECORD_HEAD.size
                    if body_at + length <= footer_at:
                        self._top_level(opcode, self._body(body_at, length))

    def _recover_chunk(self, index: ChunkIndex, damaged_at: int) -> None:
        at, length = index.chunk_start_offset, index.chunk_length - _RECORD_HEAD.size
        if at < damaged_at:
            return  # the walk indexed it
        self._file.seek(at)
        head = self._file.read(_RECORD_HEAD.size)
        if len(head) < _RECORD_HEAD.size or _RECORD_HEAD.unpack(head) != (Opcode.CHUNK, length):
            self.corrupt_chunks += 1  # the index points at zeros or at something else
            return
        self.chunks.append(ChunkInfo(at, length, index.message_start_time, index.message_end_time))
        self.recovered_chunks += 1

    def _body(self, at: int, length: int) -> ReadDataStream:
        self._file.seek(at)
        return ReadDataStream(io.BytesIO(self._file.read(length)))

    def _top_level(self, opcode: int, body: ReadDataStream) -> None:
        try:
            if opcode == Opcode.HEADER:
                self.library = Header.read(body).library
            elif opcode == Opcode.METADATA:
                metadata = Metadata.read(body)
                if metadata.name == s.METADATA_NAME:
                    self.metadata = dict(metadata.metadata)
            elif opcode == Opcode.ATTACHMENT:
                attachment = Attachment.read(body)
                if attachment.name == s.PROFILE_ATTACHMENT:
                    self.profile_toml = bytes(attachment.data)
            elif opcode == Opcode.CHANNEL:
                channel = Channel.read(body)
                self.channels[channel.id] = channel
            else:
                schema = Schema.read(body)
                self.schemas[schema.id] = schema
        except (McapError, struct.error, UnicodeDecodeError) as err:
            log.warning("%s: skipped a damaged record: %s", self.path, err)

    def _check_ours(self) -> None:
        # Every ocu recording starts with its metadata record (written, and flushed, before
        # any message); without it the topics and encodings are another tool's, and reading
        # them as ocu's would replay nothing and count their messages as the robot's.
        if self.metadata:
            return
        topics = sorted(
            {f"{c.topic} ({c.message_encoding or 'no encoding'})" for c in self.channels.values()}
        )
        shown = ", ".join(topics[:FOREIGN_TOPICS_SHOWN]) or "none"
        if len(topics) > FOREIGN_TOPICS_SHOWN:
            shown += f" and {len(topics) - FOREIGN_TOPICS_SHOWN} more"
        raise RecordingError(
            f"{self.path} is not an ocu recording (no {s.METADATA_NAME!r} metadata): "
            f"written by {self.library or 'an unnamed library'!r}, channels: {shown}"
        )

    def close(self) -> None:
        """Close the file."""
        self._file.close()

    def __enter__(self) -> Recording:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    # ---- facts -----------------------------------------------------------------------------

    @property
    def start_ns(self) -> int:
        """Log time of the first message (0 for an empty recording)."""
        return min((c.start_ns for c in self.chunks), default=0)

    @property
    def end_ns(self) -> int:
        """Log time of the last message."""
        return max((c.end_ns for c in self.chunks), default=0)

    @property
    def duration_s(self) -> float:
        """Seconds from the first to the last message."""
        return (self.end_ns - self.start_ns) / 1e9

    def topic_of(self, channel_id: int) -> str | None:
        """The topic of a channel id, None if unknown."""
        channel = self.channels.get(channel_id)
        return None if channel is None else channel.topic

    def ur_arm(self) -> UrArmProfile | None:
        """The UR arm the recording was made with (its attached profile is a UR's: it has a
        `series`; a shipped one by its name when none is attached), else None."""
        if self.profile_toml is None:
            name = self.metadata.get("profile_name", "")
            return load_ur_profile(name) if name in shipped_ur_profiles() else None
        try:
            data = tomllib.loads(self.profile_toml.decode("utf-8"))
        except (UnicodeDecodeError, tomllib.TOMLDecodeError):
            return None  # profile() says what is wrong with it
        if "series" not in data:
            return None
        try:
            arm = parse_ur_profile(data, source=f"{self.path}:{s.PROFILE_ATTACHMENT}")
        except ProfileError as err:
            raise RecordingError(f"{self.path}: recorded UR profile unusable: {err}") from err
        if arm.name in shipped_ur_profiles():
            shipped = load_ur_profile(arm.name)
            if Path(shipped.source).read_bytes() == self.profile_toml:
                return shipped  # the same file: its URDF, key map and pad mapping beside it
        return arm

    def xarm(self) -> XarmProfile | None:
        """The xArm the recording was made with (its attached profile is an xArm's: it has a
        `baud`; a shipped one by its name when none is attached), else None."""
        if self.profile_toml is None:
            name = self.metadata.get("profile_name", "")
            return load_xarm_profile(name) if name in shipped_xarm_profiles() else None
        try:
            data = tomllib.loads(self.profile_toml.decode("utf-8"))
        except (UnicodeDecodeError, tomllib.TOMLDecodeError):
            return None  # profile() says what is wrong with it
        if "baud" not in data:
            return None
        try:
            arm = parse_xarm_profile(data, source=f"{self.path}:{s.PROFILE_ATTACHMENT}")
        except ProfileError as err:
            raise RecordingError(f"{self.path}: recorded xArm profile unusable: {err}") from err
        if arm.name in shipped_xarm_profiles():
            shipped = load_xarm_profile(arm.name)
            if Path(shipped.source).read_bytes() == self.profile_toml:
                return shipped  # the same file: its key map and pad mapping beside it
        return arm

    def profile(self, fallback: RobotProfile | None = None) -> RobotProfile:
        """The robot profile the recording was made with, else `fallback`."""
        arm = self.ur_arm()
        if arm is not None:
            return ur_robot_profile(arm)
        xarm = self.xarm()
        if xarm is not None:
            return xarm_robot_profile(xarm)
        if self.profile_toml is not None:
            try:
                data = tomllib.loads(self.profile_toml.decode("utf-8"))
                return parse_profile(data, source=f"{self.path}:{s.PROFILE_ATTACHMENT}")
            except (UnicodeDecodeError, tomllib.TOMLDecodeError, ProfileError) as err:
                if fallback is None:
                    raise RecordingError(f"{self.path}: recorded profile unusable: {err}") from err
                log.warning(
                    "%s: recorded profile unusable (%s); using %s", self.path, err, fallback.source
                )
        if fallback is None:
            raise RecordingError(f"{self.path} holds no robot profile; give one")
        return fallback

    # ---- messages --------------------------------------------------------------------------

    def read_chunk(self, index: int) -> list[RecordedMessage]:
        """The messages of one chunk in file order; [] (counted) if the chunk is damaged."""
        info = self.chunks[index]
        try:
            chunk = Chunk.read(self._body(info.offset + _RECORD_HEAD.size, info.length))
            records = breakup_chunk(chunk, validate_crc=True)
        except Exception as err:
            # zstandard, lz4 and the CRC check each raise their own type for bad data.
            self.corrupt_chunks += 1
            log.warning("%s: chunk at byte %d unreadable: %s", self.path, info.offset, err)
            return []
        messages = []
        for record in records:
            if isinstance(record, Message):
                channel = self.channels.get(record.channel_id)
                if channel is None:
                    continue
                messages.append(
                    RecordedMessage(
                        channel.topic,
                        record.log_time,
                        record.publish_time,
                        record.data,
                        channel.schema_id,
                    )
                )
            elif isinstance(record, Channel):
                self.channels.setdefault(record.id, record)
            elif isinstance(record, Schema):
                self.schemas.setdefault(record.id, record)
        return messages

    def chunk_at(self, time_ns: int) -> int:
        """Index of the first chunk that holds messages at or after time_ns."""
        for index, info in enumerate(self.chunks):
            if info.end_ns >= time_ns:
                return index
        return len(self.chunks)

    def messages(
        self, topics: Iterable[str] | None = None, start_ns: int | None = None
    ) -> Iterator[RecordedMessage]:
        """Messages in file order (time order within a few ms), from start_ns on."""
        wanted = None if topics is None else set(topics)
        first = 0 if start_ns is None else self.chunk_at(start_ns)
        for index in range(first, len(self.chunks)):
            for message in self.read_chunk(index):
                if wanted is not None and message.topic not in wanted:
                    continue
                if start_ns is not None and message.log_time_ns < start_ns:
                    continue
                yield message

    def decode(self, message: RecordedMessage) -> Any:
        """The message decoded from CDR with its embedded definition (mcap-ros2-support)."""
        decoder = self._decoders.get(message.schema_id)
        if decoder is None:
            schema = self.schemas.get(message.schema_id)
            found = (
                None if schema is None else self._factory.decoder_for(s.MESSAGE_ENCODING, schema)
            )
            if found is None:
                raise RecordingError(f"{self.path}: no decoder for {message.topic}")
            decoder = found
            self._decoders[message.schema_id] = decoder
        return decoder(message.data)
