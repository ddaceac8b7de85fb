"""The xArm 1S controller board's serial protocol: frames, commands, and a resynchronising reader.

Pure: no serial port, no threads. Every layout and its source is in docs/xarm.md. A frame is
`55 55 LEN CMD PRM...` with LEN = number of parameters + 2 (the length byte and the command
byte); 16-bit numbers go low byte first (the Hiwonder document's examples and seed 003's worked
example `55 55 08 03 01 E8 03 03 20 03`, whatever the seed's prose says). The board's frames
carry no servo ID and no checksum (those belong to the servos' own bus, one layer down), so the
reader can only judge a frame by its shape: a known command whose parameters have the length
that command's layout gives (`FrameReader`).
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from ocu.protocol.errors import ProtocolError

HEADER = b"\x55\x55"
HEADER_BYTE = 0x55
#: LEN counts itself and the command byte besides the parameters.
LENGTH_OVERHEAD = 2
MAX_PARAMETERS = 255 - LENGTH_OVERHEAD
#: A servo's position range on the wire (seed 003, the Hiwonder document: 0-1000).
POSITION_MIN = 0
POSITION_MAX = 1000
#: CMD_SERVO_MOVE's duration field is 16 bits of milliseconds.
DURATION_MAX_MS = 0xFFFF
SERVO_ID_MIN = 1
SERVO_ID_MAX = 254

U16 = struct.Struct("<H")
#: Positions read back are signed (assumed: the servos' own protocol reports a signed
#: position that can go below 0 past the end of travel; docs/xarm.md).
I16 = struct.Struct("<h")


class XarmProtocolError(ProtocolError):
    """A frame or a field that does not follow the board's protocol."""


class Cmd(enum.IntEnum):
    """The board's command codes this package speaks (docs/xarm.md)."""

    SERVO_MOVE = 0x03
    ACTION_GROUP_RUN = 0x06
    ACTION_GROUP_STOP = 0x07
    GET_BATTERY_VOLTAGE = 0x0F
    MULT_SERVO_UNLOAD = 0x14
    MULT_SERVO_POS_READ = 0x15


class Direction(enum.Enum):
    """Which way a frame travels: the layouts of a request and its reply differ."""

    TO_BOARD = "to board"
    FROM_BOARD = "from board"


@dataclass(frozen=True)
class Frame:
    """One frame: its command code and parameter bytes."""

    command: int
    parameters: bytes

    def encode(self) -> bytes:
        """The frame's bytes."""
        return encode_frame(self.command, self.parameters)


def encode_frame(command: int, parameters: bytes = b"") -> bytes:
    """`55 55 LEN CMD PRM...`; XarmProtocolError for a command or length out of range."""
    if not 0 <= command <= 0xFF:
        raise XarmProtocolError(f"command {command} is not a byte")
    if len(parameters) > MAX_PARAMETERS:
        raise XarmProtocolError(f"{len(parameters)} parameters: at most {MAX_PARAMETERS}")
    return HEADER + bytes((len(parameters) + LENGTH_OVERHEAD, command)) + parameters


# ---- CMD_SERVO_MOVE ---------------------------------------------------------------------------


@dataclass(frozen=True)
class ServoMove:
    """Move each servo to its position (0-1000) within `duration_ms`, all together."""

    duration_ms: int
    positions: tuple[tuple[int, int], ...]  # (servo id, position), in frame order

    def encode(self) -> bytes:
        """The CMD_SERVO_MOVE frame."""
        return servo_move(self.duration_ms, dict(self.positions))


def _check_id(servo: int) -> None:
    if not SERVO_ID_MIN <= servo <= SERVO_ID_MAX:
        raise XarmProtocolError(f"servo id {servo} outside {SERVO_ID_MIN}-{SERVO_ID_MAX}")


def servo_move(duration_ms: int, positions: Mapping[int, int]) -> bytes:
    """CMD_SERVO_MOVE: servos (id -> position 0-1000) to their positions within duration_ms."""
    if not positions:
        raise XarmProtocolError("a move names at least one servo")
    if not 0 <= duration_ms <= DURATION_MAX_MS:
        raise XarmProtocolError(f"duration {duration_ms} ms outside 0-{DURATION_MAX_MS}")
    parameters = bytearray((len(positions),))
    parameters += U16.pack(duration_ms)
    for servo, position in positions.items():
        _check_id(servo)
        if not POSITION_MIN <= position <= POSITION_MAX:
            raise XarmProtocolError(
                f"servo {servo}: position {position} outside {POSITION_MIN}-{POSITION_MAX}"
            )
        parameters.append(servo)
        parameters += U16.pack(position)
    return encode_frame(Cmd.SERVO_MOVE, bytes(parameters))


def decode_servo_move(parameters: bytes) -> ServoMove:
    """CMD_SERVO_MOVE's parameters; XarmProtocolError if malformed."""
    if len(parameters) < 3 or len(parameters) != 3 + 3 * parameters[0] or parameters[0] == 0:
        raise XarmProtocolError(f"servo move: {len(parameters)} parameters do not fit its count")
    duration = U16.unpack_from(parameters, 1)[0]
    moves = []
    for offset in range(3, len(parameters), 3):
        servo = parameters[offset]
        position = U16.unpack_from(parameters, offset + 1)[0]
        _check_id(servo)
        if position > POSITION_MAX:
            raise XarmProtocolError(f"servo {servo}: position {position} over {POSITION_MAX}")
        moves.append((servo, position))
    return ServoMove(duration, tuple(moves))


# ---- CMD_MULT_SERVO_POS_READ -----------------------------------------------------------------


def read_positions(servos: Sequence[int]) -> bytes:
    """CMD_MULT_SERVO_POS_READ's request: the board answers with each servo's position."""
    if not servos:
        raise XarmProtocolError("a position read names at least one servo")
    for servo in servos:
        _check_id(servo)
    return encode_frame(Cmd.MULT_SERVO_POS_READ, bytes((len(servos), *servos)))


def decode_position_request(parameters: bytes) -> tuple[int, ...]:
    """The servos a position read asks for; XarmProtocolError if malformed."""
    if not parameters or parameters[0] == 0 or len(parameters) != 1 + parameters[0]:
        raise XarmProtocolError(f"position read: {len(parameters)} parameters do not fit")
    for servo in parameters[1:]:
        _check_id(servo)
    return tuple(parameters[1:])


def positions_reply(positions: Mapping[int, int]) -> bytes:
    """The board's answer to a position read: each servo's position (signed 16 bits)."""
    parameters = bytearray((len(positions),))
    for servo, position in positions.items():
        _check_id(servo)
        parameters.append(servo)
        try:
            parameters += I16.pack(position)
        except struct.error as err:
            raise XarmProtocolError(f"servo {servo}: position {position} not 16 bits") from err
    return encode_frame(Cmd.MULT_SERVO_POS_READ, bytes(parameters))


def decode_positions(parameters: bytes) -> dict[int, int]:
    """A position reply's servo -> position; XarmProtocolError if malformed."""
    if not parameters or len(parameters) != 1 + 3 * parameters[0]:
        raise XarmProtocolError(f"position reply: {len(parameters)} parameters do not fit")
    return {
        parameters[offset]: I16.unpack_from(parameters, offset + 1)[0]
        for offset in range(1, len(parameters), 3)
    }


# ---- CMD_GET_BATTERY_VOLTAGE -----------------------------------------------------------------


def read_battery() -> bytes:
    """CMD_GET_BATTERY_VOLTAGE's request (no parameters)."""
    return encode_frame(Cmd.GET_BATTERY_VOLTAGE)


def battery_reply(millivolts: int) -> bytes:
    """The board's answer: the battery voltage in millivolts."""
    if not 0 <= millivolts <= 0xFFFF:
        raise XarmProtocolError(f"battery {millivolts} mV is not 16 bits")
    return encode_frame(Cmd.GET_BATTERY_VOLTAGE, U16.pack(millivolts))


def decode_battery(parameters: bytes) -> int:
    """A battery reply's millivolts; XarmProtocolError if malformed."""
    if len(parameters) != U16.size:
        raise XarmProtocolError(f"battery reply: {len(parameters)} parameters, not 2")
    return int(U16.unpack(parameters)[0])


# ---- the other commands the board takes (named so a reader knows them) -----------------------


def unload(servos: Iterable[int]) -> bytes:
    """CMD_MULT_SERVO_UNLOAD: the servos' torque off (the arm falls: never a stop)."""
    ids = tuple(servos)
    for servo in ids:
        _check_id(servo)
    return encode_frame(Cmd.MULT_SERVO_UNLOAD, bytes((len(ids), *ids)))


# ---- the reader ------------------------------------------------------------------------------


#: Commands whose parameters start with a servo count: bytes per servo after it, per direction.
_PER_SERVO: Mapping[tuple[Direction, int], int] = {
    (Direction.TO_BOARD, Cmd.SERVO_MOVE): 3,
    (Direction.TO_BOARD, Cmd.MULT_SERVO_POS_READ): 1,
    (Direction.FROM_BOARD, Cmd.MULT_SERVO_POS_READ): 3,
    (Direction.TO_BOARD, Cmd.MULT_SERVO_UNLOAD): 1,
}
#: Bytes before the per-servo records: the count, and a move's duration.
_BEFORE_SERVOS: Mapping[int, int] = {Cmd.SERVO_MOVE: 3}
#: Commands of a fixed parameter length, per direction.
_FIXED: Mapping[tuple[Direction, int], int] = {
    (Direction.TO_BOARD, Cmd.GET_BATTERY_VOLTAGE): 0,
    (Direction.FROM_BOARD, Cmd.GET_BATTERY_VOLTAGE): U16.size,
    (Direction.TO_BOARD, Cmd.ACTION_GROUP_RUN): 3,
    (Direction.TO_BOARD, Cmd.ACTION_GROUP_STOP): 0,
}


def expected_parameters(direction: Direction, command: int, count: int | None) -> int | None:
    """How many parameters a frame of `command` has (`count`: its first parameter, if any).

    None: the count is needed to tell; -1: no such frame (unknown command, zero servos).
    """
    fixed = _FIXED.get((direction, command))
    if fixed is not None:
        return fixed
    per_servo = _PER_SERVO.get((direction, command))
    if per_servo is None:
        return -1
    if count is None:
        return None
    if count == 0:
        return -1
    return _BEFORE_SERVOS.get(command, 1) + per_servo * count


class FrameReader:
    """Whole frames out of a serial byte stream that arrives in arbitrary pieces.

    Without a checksum a frame is judged by its shape: the header, a command known in this
    direction, and a length byte equal to what that command's layout gives (for a command
    with a servo count, once the count has arrived). All of it is judged before the rest of
    the frame is waited for, so a corrupt length does not hold the stream up. A candidate that
    fails is dropped one byte at a time, so the reader regains sync at the next good header;
    `bad_frames` counts each such episode, `skipped_bytes` the bytes lost.
    """

    def __init__(self, direction: Direction, *, keep_skipped: bool = False) -> None:
        self.direction = direction
        # Whether skipped bytes are kept for take_skipped (a link that records them).
        self.keep_skipped = keep_skipped
        self._buffer = bytearray()
        self._in_garbage = False
        self.bad_frames = 0
        self.skipped_bytes = 0
        self.frames = 0
        # Runs of skipped bytes: (how many of the next feed's frames came before, bytes).
        self._skipped: list[tuple[int, bytes]] = []

    @property
    def pending(self) -> int:
        """Bytes held waiting for the rest of a frame."""
        return len(self._buffer)

    def _judge(self, offset: int) -> int:
        """At `offset`: -1 bad, 0 incomplete (wait), else the whole frame's length."""
        buffer = self._buffer
        available = len(buffer) - offset
        if buffer[offset] != HEADER_BYTE:
            return -1
        if available < 2:
            return 0
        if buffer[offset + 1] != HEADER_BYTE:
            return -1
        if available < 4:
            return 0
        declared = buffer[offset + 2] - LENGTH_OVERHEAD
        if declared < 0:
            return -1
        command = buffer[offset + 3]
        expected = expected_parameters(self.direction, command, None)
        if expected is None:
            if declared < 1:
                return -1
            if available < 5:
                return 0
            expected = expected_parameters(self.direction, command, buffer[offset + 4])
        if expected != declared:
            return -1
        total = 4 + declared
        return total if available >= total else 0

    def feed(self, data: bytes) -> list[Frame]:
        """Add received bytes; the whole frames now complete, in order."""
        self._buffer += data
        frames: list[Frame] = []
        run = bytearray()
        offset = 0
        while offset < len(self._buffer):
            verdict = self._judge(offset)
            if verdict == 0:
                break
            if verdict < 0:
                if not self._in_garbage:
                    self._in_garbage = True
                    self.bad_frames += 1
                if self.keep_skipped:
                    run.append(self._buffer[offset])
                offset += 1
                self.skipped_bytes += 1
                continue
            self._in_garbage = False
            if run:
                self._skipped.append((len(frames), bytes(run)))
                run = bytearray()
            frame_bytes = self._buffer[offset : offset + verdict]
            frames.append(Frame(frame_bytes[3], bytes(frame_bytes[4:])))
            self.frames += 1
            offset += verdict
        if run:
            self._skipped.append((len(frames), bytes(run)))
        del self._buffer[:offset]
        return frames

    def take_skipped(self) -> list[tuple[int, bytes]]:
        """The runs of bytes skipped by the last feed (with `keep_skipped`: garbage, for a
        recording): each with how many of that feed's frames came before it."""
        skipped, self._skipped = self._skipped, []
        return skipped
