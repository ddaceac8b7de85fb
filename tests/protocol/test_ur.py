"""UR codecs against golden bytes written by hand from the layouts in docs/ur.md, round trips,
the stream splitter over arbitrary TCP pieces, and every malformed input.

Golden bytes are assembled field by field with hex literals (big-endian IEEE doubles), never
with struct: 1.0 = 3ff0000000000000, 2.0 = 4000000000000000, -1.5 = bff8000000000000,
7.0 = 401c000000000000, 3.0 = 4008000000000000, 0.5 = 3fe0000000000000.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ocu.protocol.errors import ProtocolError
from ocu.protocol.ur import (
    KNOWN_REALTIME_SIZES,
    JointData,
    JointState,
    MasterboardData,
    RealtimeState,
    RobotMode,
    RobotModeData,
    RobotState,
    SafetyMode,
    StreamSplitter,
    UnknownPackage,
    UnknownSubPackage,
    UrProtocolError,
    VersionMessage,
    decode_primary,
    movej,
    parse_script_line,
    realtime_size,
    realtime_state,
    servoj,
    speedj,
    stopj,
)

ZERO = "0000000000000000"
ONE = "3ff0000000000000"
TWO = "4000000000000000"
MINUS_1_5 = "bff8000000000000"
SEVEN = "401c000000000000"
THREE = "4008000000000000"
HALF = "3fe0000000000000"


def _realtime_golden(size: int) -> bytes:
    """A realtime packet of `size` bytes: time 2.0, q_actual[0] -1.5, robot mode 7, safety 3."""
    doubles = [ZERO] * ((size - 4) // 8)
    doubles[0] = TWO  # @4 time
    doubles[1 + 5 * 6] = MINUS_1_5  # @252 q_actual[0]: after time and 5 six-vectors
    doubles[1 + 7 * 6 + 5] = HALF  # @388 i_actual[5]
    doubles[1 + 9 * 6 + 2] = ONE  # @460 tool_vector_actual z
    doubles[94] = SEVEN  # @756 robot mode
    doubles[101] = THREE  # @812 safety mode
    return bytes.fromhex(f"{size:08x}" + "".join(doubles))


def test_realtime_sizes_by_version() -> None:
    assert realtime_size((3, 1)) == 1044
    assert realtime_size((3, 2)) == 1060
    assert realtime_size((3, 5)) == 1108
    assert realtime_size((5, 3)) == 1108
    assert realtime_size((3, 10)) == 1116
    assert realtime_size((5, 4)) == 1116
    assert realtime_size((3, 15)) == 1140
    assert realtime_size((5, 9)) == 1140
    assert realtime_size((5, 10)) == 1220
    assert realtime_size((5, 23)) == 1220
    with pytest.raises(
        UrProtocolError, match=r"no known realtime layout for controller version 1\.8"
    ):
        realtime_size((1, 8))


@pytest.mark.parametrize("size", sorted(KNOWN_REALTIME_SIZES))
def test_realtime_golden_decode_and_round_trip(size: int) -> None:
    golden = _realtime_golden(size)
    state = RealtimeState.decode(golden)
    assert state.size == size
    assert state.time_s == 2.0
    assert state.q_actual == (-1.5, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert state.i_actual[5] == 0.5
    assert state.tool_vector_actual[2] == 1.0
    assert state.mode is RobotMode.RUNNING
    assert state.safety is SafetyMode.PROTECTIVE_STOP
    assert (state.digital_outputs is None) == (size < 1060)
    assert (state.safety_status is None) == (size < 1116)
    assert (state.payload_mass_kg is None) == (size < 1220)
    assert state.encode() == golden


def test_realtime_unused_values_round_trip() -> None:
    doubles = [ZERO] * ((1060 - 4) // 8)
    doubles[93] = ONE  # @748 "test value", used by UR only
    doubles[94] = SEVEN
    doubles[101] = ONE
    golden = bytes.fromhex("00000424" + "".join(doubles))
    state = RealtimeState.decode(golden)
    assert state.unused[0] == 1.0
    assert state.encode() == golden


def test_realtime_state_defaults_encode_to_size() -> None:
    state = realtime_state(1220, q_actual=(1.0, 2.0, 3.0, 4.0, 5.0, 6.0), payload_mass_kg=1.5)
    data = state.encode()
    assert len(data) == 1220
    assert data[:4] == bytes.fromhex("000004c4")
    assert data[252:260] == bytes.fromhex(ONE)
    assert RealtimeState.decode(data) == state


def test_realtime_malformed() -> None:
    good = _realtime_golden(1060)
    with pytest.raises(UrProtocolError, match="no length field"):
        RealtimeState.decode(b"\x00\x00")
    with pytest.raises(UrProtocolError, match="length field says 1060 bytes, got 1059"):
        RealtimeState.decode(good[:-1])
    with pytest.raises(UrProtocolError, match="1060 bytes, expected 1220 for this controller"):
        RealtimeState.decode(good, expected_size=1220)
    odd = bytes.fromhex("0000000c") + bytes.fromhex(ZERO)
    with pytest.raises(UrProtocolError, match="12 bytes matches no known layout"):
        RealtimeState.decode(odd)
    bad_mode = bytearray(good)
    bad_mode[756:764] = bytes.fromhex("401e000000000000")  # 7.5
    with pytest.raises(UrProtocolError, match=r"robot mode 7\.5 is not a whole number"):
        RealtimeState.decode(bytes(bad_mode))
    nan_safety = bytearray(good)
    nan_safety[812:820] = bytes.fromhex("7ff8000000000000")
    with pytest.raises(UrProtocolError, match="safety mode nan is not a whole number"):
        RealtimeState.decode(bytes(nan_safety))
    with pytest.raises(UrProtocolError, match="payload_mass_kg is not in the 1060-byte layout"):
        realtime_state(1060, payload_mass_kg=1.0)
    assert issubclass(UrProtocolError, ProtocolError)


# ---- primary / secondary ---------------------------------------------------------------------

VERSION_GOLDEN = bytes.fromhex(
    "0000002b"  # @0  length 43
    "14"  # @4  type 20: robot message
    "0000000000000064"  # @5  timestamp 100 µs
    "fe"  # @13 source -2
    "03"  # @14 message type 3: version
    "09"  # @15 project name length 9
    + b"URControl".hex()  # @16
    + "05"  # @25 major 5
    "0a"  # @26 minor 10
    "00000002"  # @27 bugfix 2
    "000004d2"  # @31 build 1234
     + b"2024-1-1".hex()  # @35 build date, the rest of the packet
)


def test_version_message_golden() -> None:
    message = VersionMessage.decode(VERSION_GOLDEN)
    assert message == VersionMessage(
        "URControl", 5, 10, 2, 1234, "2024-1-1", timestamp_us=100, source=-2
    )
    assert message.version == (5, 10)
    assert decode_primary(VERSION_GOLDEN) == message
    assert message.encode() == VERSION_GOLDEN


def test_version_message_malformed() -> None:
    good = VersionMessage("URControl", 3, 2, 0, 1).encode()
    with pytest.raises(UrProtocolError, match="shorter than its header"):
        VersionMessage.decode(good[:3])
    with pytest.raises(UrProtocolError, match="length field says 35 bytes, got 34"):
        VersionMessage.decode(good[:-1])
    wrong_type = good[:4] + b"\x10" + good[5:]
    with pytest.raises(UrProtocolError, match="packet type 16, expected 20"):
        VersionMessage.decode(wrong_type)
    not_version = good[:14] + b"\x06" + good[15:]
    with pytest.raises(UrProtocolError, match="robot message type 6 is not a version message"):
        VersionMessage.decode(not_version)
    long_name = good[:15] + b"\x7f" + good[16:]
    with pytest.raises(UrProtocolError, match="project name of 127 bytes overruns the packet"):
        VersionMessage.decode(long_name)
    with pytest.raises(UrProtocolError, match="over 127"):
        VersionMessage("x" * 128, 5, 0, 0, 0).encode()


ROBOT_MODE_47 = bytes.fromhex(
    "0000002f"  # @0  sub-package length 47
    "00"  # @4  type 0: robot mode data
    "00000000000003e8"  # @5  timestamp 1000 µs
    "01"  # @13 real robot connected
    "01"  # @14 real robot enabled
    "01"  # @15 power on
    "00"  # @16 emergency stopped
    "01"  # @17 protective stopped
    "01"  # @18 program running
    "00"  # @19 program paused
    "07"  # @20 robot mode 7 (running)
    "00"  # @21 control mode
    + ONE  # @22 target speed fraction
    + HALF  # @30 speed scaling
    + ONE  # @38 target speed fraction limit
    + "00"  # @46 reserved
)

JOINT = (
    MINUS_1_5  # q actual
    + ONE  # q target
    + HALF  # qd actual
    + "3f800000"  # current 1.0 (float)
    + "42400000"  # voltage 48.0
    + "420c0000"  # motor temperature 35.0
    + "00000000"  # micro temperature (obsolete)
    + "fd"  # joint mode 253
)
JOINT_DATA = bytes.fromhex("000000fb01" + JOINT * 6)  # 251 bytes

MASTERBOARD = bytes.fromhex(
    "00000044"  # @0  length 68
    "03"  # @4  type 3: masterboard data
    "00000005"  # @5  digital inputs
    "00000002"  # @9  digital outputs
    "00"  # @13 analog input range 0
    "01"  # @14 analog input range 1
    + ZERO  # @15 analog input 0
    + ONE  # @23 analog input 1
    + "00"  # @31 analog output domain 0
    "01"  # @32 analog output domain 1
    + ZERO  # @33 analog output 0
    + ZERO  # @41 analog output 1
    + "420c0000"  # @49 temperature 35.0
    "42400000"  # @53 48 V
    "3f800000"  # @57 robot current 1.0
    "00000000"  # @61 I/O current
    "03"  # @65 safety mode 3: protective stop
    "00"  # @66 in reduced mode
    "00"  # @67 euromap67/IMMI installed: no
)


def test_robot_state_golden() -> None:
    unknown = bytes.fromhex("0000000709abcd")  # a sub-package the OCU does not read
    body = ROBOT_MODE_47 + JOINT_DATA + MASTERBOARD + unknown
    packet = (5 + len(body)).to_bytes(4, "big") + b"\x10" + body
    state = RobotState.decode(packet)
    mode = state.robot_mode
    assert mode is not None
    assert mode.protective_stopped
    assert mode.program_running
    assert not mode.emergency_stopped
    assert mode.robot_mode == RobotMode.RUNNING
    assert mode.speed_scaling == 0.5
    joints = state.joint_data
    assert joints is not None
    assert joints.joints[0] == JointState(-1.5, 1.0, 0.5, 1.0, 48.0, 35.0, 0.0, 253)
    board = state.masterboard
    assert board is not None
    assert board.safety is SafetyMode.PROTECTIVE_STOP
    assert board.digital_input_bits == 5
    assert state.packages[3] == UnknownSubPackage(9, unknown)
    assert state.encode() == packet
    assert decode_primary(packet) == state


def test_robot_mode_layouts_by_size() -> None:
    old = RobotModeData(target_speed_fraction_limit=None, reserved=None)
    assert len(old.encode()) == 38
    assert RobotModeData.decode(old.encode()) == old
    mid = RobotModeData(reserved=None)
    assert len(mid.encode()) == 46
    assert RobotModeData.decode(mid.encode()) == mid
    assert RobotModeData.decode(ROBOT_MODE_47).encode() == ROBOT_MODE_47


def test_masterboard_with_immi_block_and_tail() -> None:
    board = MasterboardData(safety_mode=SafetyMode.REDUCED, immi=(1, 2, 24.0, 0.5), tail=b"\x01")
    data = board.encode()
    assert len(data) == 68 + 16 + 1
    assert MasterboardData.decode(data) == board


def test_robot_state_malformed() -> None:
    def packet(body: bytes) -> bytes:
        return (5 + len(body)).to_bytes(4, "big") + b"\x10" + body

    with pytest.raises(UrProtocolError, match="too few for a sub-package"):
        RobotState.decode(packet(b"\x00\x00"))
    overrun = bytes.fromhex("000000ff") + ROBOT_MODE_47[4:]
    with pytest.raises(UrProtocolError, match="sub-package type 0 says 255 bytes at offset 5"):
        RobotState.decode(packet(overrun))
    tiny = bytes.fromhex("00000003") + b"\x00"
    with pytest.raises(UrProtocolError, match="says 3 bytes"):
        RobotState.decode(packet(tiny))
    short_mode = bytes.fromhex("0000002d") + ROBOT_MODE_47[4:45]
    with pytest.raises(UrProtocolError, match=r"robot mode data of 45 bytes \(known: 38, 46, 47\)"):
        RobotState.decode(packet(short_mode))
    bad_mode = ROBOT_MODE_47[:20] + b"\x09" + ROBOT_MODE_47[21:]
    with pytest.raises(UrProtocolError, match="robot mode 9 is not a known robot mode"):
        RobotState.decode(packet(bad_mode))
    short_joints = bytes.fromhex("000000fa") + JOINT_DATA[4:250]
    with pytest.raises(UrProtocolError, match="joint data of 250 bytes, expected 251"):
        RobotState.decode(packet(short_joints))
    bad_safety = MASTERBOARD[:65] + b"\x15" + MASTERBOARD[66:]
    with pytest.raises(UrProtocolError, match="safety mode 21 is not a known safety mode"):
        RobotState.decode(packet(bad_safety))
    cut_immi = MASTERBOARD[:67] + b"\x01"
    with pytest.raises(UrProtocolError, match="the IMMI block is cut short"):
        RobotState.decode(packet(cut_immi))
    with pytest.raises(UrProtocolError, match="joint data has 5 joints"):
        JointData((JointState(),) * 5)
    with pytest.raises(UrProtocolError, match="length field says 9 bytes, got 10"):
        decode_primary(bytes.fromhex("00000009") + b"\x10" + b"\x00" * 5)


def test_unknown_primary_package_is_kept() -> None:
    data = bytes.fromhex("0000000819010203")  # type 25: program state message
    assert decode_primary(data) == UnknownPackage(25, data)


# ---- the stream splitter ---------------------------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(cuts=st.lists(st.integers(min_value=1, max_value=400), min_size=1, max_size=30))
def test_splitter_reassembles_any_pieces(cuts: list[int]) -> None:
    stream = _realtime_golden(1220) * 3
    splitter = StreamSplitter.realtime({1220})
    packets: list[bytes] = []
    offset = 0
    for cut in cuts * 20:
        packets += splitter.feed(stream[offset : offset + cut])
        offset += cut
        if offset >= len(stream):
            break
    packets += splitter.feed(stream[offset:])
    assert packets == [_realtime_golden(1220)] * 3
    assert splitter.malformed == 0
    assert splitter.pending == 0


def test_splitter_regains_sync_after_garbage_and_bad_lengths() -> None:
    good = _realtime_golden(1116)
    bad_length = bytes.fromhex("00000400") + good[4:]  # 1024: no layout has it
    splitter = StreamSplitter.realtime({1116})
    packets = splitter.feed(good + b"\xde\xad\xbe" + good + bad_length + good)
    assert packets == [good, good, good]
    assert splitter.malformed == 2
    assert splitter.skipped_bytes == 3 + len(bad_length)


def test_primary_splitter_skips_garbage_and_keeps_packets() -> None:
    version = VersionMessage("URControl", 5, 10, 0, 0).encode()
    state = RobotState((RobotModeData(),)).encode()
    splitter = StreamSplitter.primary()
    garbage = bytes.fromhex("7fffffff10") + b"junk"  # an impossible length
    out: list[bytes] = []
    data = version + garbage + state + state
    for i in range(0, len(data), 5):
        out += splitter.feed(data[i : i + 5])
    assert out == [version, state, state]
    assert splitter.malformed == 1
    assert splitter.skipped_bytes == len(garbage)


# ---- URScript --------------------------------------------------------------------------------


def test_script_commands_golden() -> None:
    assert speedj([0.1, 0, 0, 0, 0, -0.25], 1.5, 0.008) == (
        b"speedj([0.100000,0.000000,0.000000,0.000000,0.000000,-0.250000],1.500000,0.008000)\n"
    )
    assert stopj(2.0) == b"stopj(2.000000)\n"
    assert servoj([0.0] * 6, 0.008, 0.03, 500) == (
        b"servoj([0.000000,0.000000,0.000000,0.000000,0.000000,0.000000],0,0,0.008000,"
        b"0.030000,500.000000)\n"
    )
    assert movej([1.0] * 6, 1.2, 0.5).startswith(b"movej([1.000000,")


def test_script_round_trip() -> None:
    command = parse_script_line(speedj([0.1, 0, 0, 0, 0, -0.25], 1.5, 0.008).decode())
    assert command.name == "speedj"
    assert command.qd == (0.1, 0.0, 0.0, 0.0, 0.0, -0.25)
    assert (command.a, command.t) == (1.5, 0.008)
    servo = parse_script_line(servoj([0.5] * 6, 0.008, 0.03, 500).decode())
    assert servo.q == (0.5,) * 6
    assert (servo.lookahead_time, servo.gain) == (0.03, 500)
    move = parse_script_line("movej([0,0,0,0,0,1e-1], v=0.5)")
    assert move.q == (0, 0, 0, 0, 0, 0.1)
    assert (move.a, move.v) == (1.4, 0.5)
    assert parse_script_line("stopj(3)").a == 3.0


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("", "not a URScript call"),
        ("\x00\xff garbage", "not a URScript call"),
        ("set_digital_out(1, True)", r"set_digital_out\(\) is not in the simulator's URScript"),
        ("speedj([0,0,0,0,0], 1.0, 0.1)", "qd must be a list of 6 numbers"),
        ("speedj(1.0, 1.0, 0.1)", "qd must be a list of 6 joint values"),
        ("speedj([0,0,0,0,0,0])", r"speedj\(\): a is required"),
        ("speedj([0,0,0,0,0,0], [1,1,1,1,1,1], 0.1)", "a is a number, not a list"),
        ("speedj([0,0,0,0,0,0], 1.0, -0.1)", "t must be >= 0"),
        ("speedj([0,0,0,0,0,0], 1.0, 0.1, 4)", "takes at most 3 arguments"),
        ("speedj([0,0,0,0,0,0], a=1.0, 0.1)", "a positional argument after a keyword one"),
        ("speedj([0,0,0,0,0,0], 1.0, x=1)", "has no parameter 'x'"),
        ("speedj([0,0,0,0,0,0], a=1.0, a=2.0)", "a given twice"),
        ("movej(p[0,0,0,0,0,0], 1.0, 1.0)", "cannot read the arguments"),
        ("stopj(0)", "stopj\\(\\): a must be > 0"),
        ("speedj([nan,0,0,0,0,0], 1, 0.1)", "must be a list of 6 numbers"),
    ],
)
def test_script_malformed(line: str, message: str) -> None:
    with pytest.raises(UrProtocolError, match=message):
        parse_script_line(line)


def test_script_encoders_refuse_bad_values() -> None:
    with pytest.raises(UrProtocolError, match="qd has 5 values"):
        speedj([0.0] * 5, 1.0, 0.1)
    with pytest.raises(UrProtocolError, match="non-finite value nan"):
        speedj([math.nan] + [0.0] * 5, 1.0, 0.1)
    with pytest.raises(UrProtocolError, match="a must be finite and > 0"):
        stopj(0.0)
    with pytest.raises(UrProtocolError, match="t must be finite and >= 0"):
        speedj([0.0] * 6, 1.0, -1.0)
