"""The xArm board's codec against golden bytes written by hand from docs/xarm.md (seed 003's
worked example, the Hiwonder document's examples), round trips, and the frame reader over
arbitrary pieces and garbage.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ocu.protocol.errors import ProtocolError
from ocu.protocol.xarm import (
    Cmd,
    Direction,
    Frame,
    FrameReader,
    ServoMove,
    XarmProtocolError,
    battery_reply,
    decode_battery,
    decode_position_request,
    decode_positions,
    decode_servo_move,
    encode_frame,
    positions_reply,
    read_battery,
    read_positions,
    servo_move,
    unload,
)

# Seed 003, Table 2.1's worked example: servo 3 to 800 within 1000 ms, low bytes first.
SEED_EXAMPLE = bytes.fromhex("55 55 08 03 01 E8 03 03 20 03")
# The Hiwonder document's second example: servos 2 and 9 to 800 within 800 ms.
HIWONDER_TWO_SERVOS = bytes.fromhex("55 55 0B 03 02 20 03 02 20 03 09 20 03")


def test_servo_move_encodes_seed_003_worked_example() -> None:
    assert servo_move(1000, {3: 800}) == SEED_EXAMPLE


def test_servo_move_encodes_two_servos_as_the_board_document() -> None:
    assert servo_move(800, {2: 800, 9: 800}) == HIWONDER_TWO_SERVOS


def test_servo_move_decodes_the_worked_example() -> None:
    frames = FrameReader(Direction.TO_BOARD).feed(SEED_EXAMPLE)
    assert frames == [Frame(Cmd.SERVO_MOVE, SEED_EXAMPLE[4:])]
    assert decode_servo_move(frames[0].parameters) == ServoMove(1000, ((3, 800),))
    assert ServoMove(1000, ((3, 800),)).encode() == SEED_EXAMPLE


def test_position_read_and_reply_golden() -> None:
    assert read_positions([6, 5]) == bytes.fromhex("55 55 05 15 02 06 05")
    assert decode_position_request(bytes.fromhex("02 06 05")) == (6, 5)
    reply = positions_reply({6: 500, 5: -3})
    assert reply == bytes.fromhex("55 55 09 15 02 06 F4 01 05 FD FF")
    assert decode_positions(reply[4:]) == {6: 500, 5: -3}


def test_battery_golden() -> None:
    assert read_battery() == bytes.fromhex("55 55 02 0F")
    assert battery_reply(7400) == bytes.fromhex("55 55 04 0F E8 1C")
    assert decode_battery(bytes.fromhex("E8 1C")) == 7400


def test_unload_golden() -> None:
    assert unload([1, 2]) == bytes.fromhex("55 55 05 14 02 01 02")


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: servo_move(1000, {}), "at least one servo"),
        (lambda: servo_move(70000, {1: 500}), "duration"),
        (lambda: servo_move(-1, {1: 500}), "duration"),
        (lambda: servo_move(100, {1: 1001}), "position 1001"),
        (lambda: servo_move(100, {0: 500}), "servo id 0"),
        (lambda: read_positions([]), "at least one servo"),
        (lambda: positions_reply({1: 40000}), "not 16 bits"),
        (lambda: battery_reply(70000), "not 16 bits"),
        (lambda: encode_frame(256), "not a byte"),
        (lambda: encode_frame(3, bytes(254)), "at most 253"),
        (lambda: decode_servo_move(bytes.fromhex("02 E8 03 03 20 03")), "do not fit"),
        (lambda: decode_servo_move(bytes.fromhex("01 E8 03 03 E9 03")), "over 1000"),
        (lambda: decode_positions(bytes.fromhex("02 06 F4 01")), "do not fit"),
        (lambda: decode_position_request(b""), "do not fit"),
        (lambda: decode_battery(b"\x01"), "not 2"),
    ],
)
def test_malformed_input_raises(call: object, match: str) -> None:
    with pytest.raises(XarmProtocolError, match=match):
        call()  # type: ignore[operator]
    assert issubclass(XarmProtocolError, ProtocolError)


def test_reader_skips_garbage_and_counts_one_bad_episode() -> None:
    reader = FrameReader(Direction.TO_BOARD)
    frames = reader.feed(b"\x12\x55\x34\x55\x55\x01" + SEED_EXAMPLE + b"\xff" + read_battery())
    assert [f.command for f in frames] == [Cmd.SERVO_MOVE, Cmd.GET_BATTERY_VOLTAGE]
    assert reader.bad_frames == 2
    assert reader.skipped_bytes == 7
    assert reader.pending == 0


def test_reader_rejects_a_length_that_disagrees_with_the_count_without_waiting() -> None:
    # LEN 0xFF for a one-servo move: judged at once, the next frame is not swallowed.
    reader = FrameReader(Direction.TO_BOARD)
    assert reader.feed(bytes.fromhex("55 55 FF 03 01") + SEED_EXAMPLE) == [
        Frame(Cmd.SERVO_MOVE, SEED_EXAMPLE[4:])
    ]
    assert reader.bad_frames == 1


def test_reader_knows_the_direction() -> None:
    # A battery request has no parameters; the reply has two: each reader takes its own.
    assert FrameReader(Direction.FROM_BOARD).feed(read_battery()) == []
    assert FrameReader(Direction.TO_BOARD).feed(battery_reply(7000)) == []
    assert FrameReader(Direction.FROM_BOARD).feed(battery_reply(7000)) == [
        Frame(Cmd.GET_BATTERY_VOLTAGE, bytes.fromhex("58 1B"))
    ]


def test_reader_waits_for_a_frame_split_anywhere() -> None:
    for cut in range(1, len(SEED_EXAMPLE)):
        reader = FrameReader(Direction.TO_BOARD)
        assert reader.feed(SEED_EXAMPLE[:cut]) == []
        assert reader.pending == cut
        assert reader.feed(SEED_EXAMPLE[cut:]) == [Frame(Cmd.SERVO_MOVE, SEED_EXAMPLE[4:])]
        assert reader.bad_frames == 0


_positions = st.dictionaries(st.integers(1, 6), st.integers(-2000, 3000), min_size=1, max_size=6)


@settings(max_examples=200, deadline=None)
@given(
    replies=st.lists(
        st.one_of(
            _positions.map(positions_reply),
            st.integers(0, 0xFFFF).map(battery_reply),
        ),
        min_size=1,
        max_size=8,
    ),
    garbage=st.lists(st.binary(max_size=12), min_size=8, max_size=8),
    cuts=st.lists(st.integers(1, 7), min_size=1, max_size=40),
)
def test_reader_recovers_every_frame_between_garbage_in_any_pieces(
    replies: list[bytes], garbage: list[bytes], cuts: list[int]
) -> None:
    """Garbage that contains no header byte between frames costs no frame; the frames come
    out whole, in order, whatever pieces the serial port hands over."""
    stream = b""
    for reply, junk in zip(replies, garbage, strict=False):
        stream += junk.replace(b"\x55", b"\x00") + reply
    reader = FrameReader(Direction.FROM_BOARD)
    frames: list[Frame] = []
    offset = 0
    index = 0
    while offset < len(stream):
        step = cuts[index % len(cuts)]
        frames += reader.feed(stream[offset : offset + step])
        offset += step
        index += 1
    assert [frame.encode() for frame in frames] == replies
    assert reader.pending == 0


@settings(max_examples=300, deadline=None)
@given(junk=st.binary(max_size=64), move=st.integers(0, 1000))
def test_reader_resynchronises_after_any_garbage(junk: bytes, move: int) -> None:
    """Whatever garbage comes first (headers in it included), the reader is back in sync
    within the longest frame (257 bytes): the good frames after that come out whole. Without
    a checksum a frame straddling garbage and good bytes can look well shaped; the sync is
    what is promised, not that no such frame is ever handed on."""
    frame = servo_move(200, {6: move})
    reader = FrameReader(Direction.TO_BOARD)
    frames = reader.feed(junk + frame * 30)
    good = Frame(Cmd.SERVO_MOVE, frame[4:])
    assert frames[-4:] == [good] * 4
    assert reader.pending == 0


def test_the_reader_keeps_each_run_of_skipped_bytes_where_it_came() -> None:
    """For a recording: each run of garbage with how many of the feed's frames came before
    it, so that the runs and the frames can be written in the order the bytes came."""
    one, two = battery_reply(7400), positions_reply({6: 500})
    reader = FrameReader(Direction.FROM_BOARD, keep_skipped=True)
    frames = reader.feed(b"\x01\x02" + one + b"\x55\x03" + two + b"\x04")
    assert [f.encode() for f in frames] == [one, two]
    assert reader.take_skipped() == [(0, b"\x01\x02"), (1, b"\x55\x03"), (2, b"\x04")]
    assert reader.take_skipped() == []
    assert reader.bad_frames == 3
    # Without keep_skipped nothing is kept (a reader nobody records).
    plain = FrameReader(Direction.FROM_BOARD)
    plain.feed(b"\x01" + one)
    assert plain.take_skipped() == []
