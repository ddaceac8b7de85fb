"""SI commands to RCP axes and buttons, velocity limits, and telemetry to radians."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ocu.control.commands import VelocityLimits
from ocu.profile import Motor, load_profile, load_profile_data, parse_profile
from ocu.protocol import Codec, MotorRecord, RemoteControlPacket, TelemetryPacket
from ocu.protocol.mapping import (
    CommandMapper,
    rad_to_ticks,
    read_motor,
    read_telemetry,
    ticks_to_rad,
)
from ocu.protocol.wire import make_codec
from ocu.records import Command, CommandError

PROFILE = load_profile()
MAPPER = CommandMapper(PROFILE)

# Paper constants (seed 000, section 3.1), written out so the test does not trust the profile.
LINEAR_AXIS_PER_M_S = 71553.837
ROTATION_AXIS_PER_RAD_S = 25171.216

CHANNEL_NAMES = tuple(load_profile().channels)


@pytest.fixture
def limits() -> VelocityLimits:
    return VelocityLimits(PROFILE)


def _axis(packet: RemoteControlPacket, channel: str) -> int:
    return packet.axes[PROFILE.channels[channel].axis]


def _other_axes(packet: RemoteControlPacket, channel: str) -> list[int]:
    index = PROFILE.channels[channel].axis
    return [value for i, value in enumerate(packet.axes) if i != index]


def _waist() -> Motor:
    return PROFILE.motors["waist"]


# --- SI to axis ---------------------------------------------------------------------------


def test_make_codec_uses_the_profile_frame_types() -> None:
    assert make_codec(PROFILE) == Codec(rcp_type=0x01, telemetry_type=0x02, video_type=0x03)


def test_zero_command_is_a_zero_packet() -> None:
    assert MAPPER.to_packet(Command()) == RemoteControlPacket()


@pytest.mark.parametrize(
    ("channel", "speed", "axis_value"),
    [
        ("drive_linear", 0.2, round(0.2 * LINEAR_AXIS_PER_M_S)),  # 14311
        ("drive_linear", -0.2, -14311),
        ("drive_linear", 0.01, round(0.01 * LINEAR_AXIS_PER_M_S)),  # 716
        ("drive_turn", 0.5, round(0.5 * ROTATION_AXIS_PER_RAD_S)),  # 12586
        ("drive_turn", -0.5, -12586),
    ],
)
def test_si_to_axis_with_the_paper_constants(channel: str, speed: float, axis_value: int) -> None:
    packet = MAPPER.to_packet(Command(velocities={channel: speed}))
    assert _axis(packet, channel) == axis_value
    assert _other_axes(packet, channel) == [0] * 15


def test_drive_channels_use_their_profile_axes() -> None:
    packet = MAPPER.to_packet(Command(velocities={"drive_linear": 0.2, "drive_turn": 0.5}))
    assert packet.axes[PROFILE.channels["drive_linear"].axis] == 14311
    assert packet.axes[PROFILE.channels["drive_turn"].axis] == 12586


@pytest.mark.parametrize(
    "channel", [c for c in CHANNEL_NAMES if c not in (load_profile().drive_channels or ())]
)
def test_joint_channels_use_the_joint_scale(channel: str) -> None:
    per_rad_s = PROFILE.channels[channel].axis_per_unit
    packet = MAPPER.to_packet(Command(velocities={channel: -0.25}))
    assert _axis(packet, channel) == round(-0.25 * per_rad_s)


def test_clamped_to_current_limits(limits: VelocityLimits) -> None:
    assert limits.get("drive_linear") == PROFILE.channels["drive_linear"].default_max == 0.3
    packet = MAPPER.to_packet(Command(velocities={"drive_linear": 0.4}), limits)
    assert _axis(packet, "drive_linear") == round(0.3 * LINEAR_AXIS_PER_M_S)  # 21466
    packet = MAPPER.to_packet(Command(velocities={"drive_linear": -0.4}), limits)
    assert _axis(packet, "drive_linear") == -21466
    limits.set("drive_linear", 0.1)
    packet = MAPPER.to_packet(Command(velocities={"drive_linear": 0.2}), limits)
    assert _axis(packet, "drive_linear") == round(0.1 * LINEAR_AXIS_PER_M_S)  # 7155


def test_clamped_to_hard_max_without_limits() -> None:
    packet = MAPPER.to_packet(Command(velocities={"drive_linear": 10.0, "drive_turn": -100.0}))
    assert _axis(packet, "drive_linear") == round(0.45 * LINEAR_AXIS_PER_M_S)  # 32199
    assert _axis(packet, "drive_turn") == round(-1.3 * ROTATION_AXIS_PER_RAD_S)  # -32723


@pytest.mark.parametrize("channel", CHANNEL_NAMES)
def test_full_stick_never_leaves_the_int16_range(channel: str, limits: VelocityLimits) -> None:
    hard_max = PROFILE.channels[channel].hard_max
    limits.set(channel, hard_max)
    for speed in (1e9, -1e9):
        packet = MAPPER.to_packet(Command(velocities={channel: speed}), limits)
        expected = round(math.copysign(hard_max, speed) * PROFILE.channels[channel].axis_per_unit)
        assert _axis(packet, channel) == expected
        assert -32767 <= expected <= 32767
        packet.encode(0x01)


# --- limits -------------------------------------------------------------------------------


def test_limits_start_at_the_defaults(limits: VelocityLimits) -> None:
    assert limits.as_dict() == {n: c.default_max for n, c in PROFILE.channels.items()}


def test_limits_set_clips_to_zero_and_hard_max(limits: VelocityLimits) -> None:
    assert limits.set("drive_linear", 5.0) == 0.45
    assert limits.get("drive_linear") == 0.45
    assert limits.set("drive_linear", -1.0) == 0.0
    assert limits.get("drive_linear") == 0.0
    assert limits.set("waist", 0.25) == 0.25
    assert limits.get("waist") == 0.25


def test_limits_clamp_keeps_sign(limits: VelocityLimits) -> None:
    assert limits.clamp("drive_turn", 5.0) == 0.8
    assert limits.clamp("drive_turn", -5.0) == -0.8
    assert limits.clamp("drive_turn", 0.1) == 0.1


def test_limits_as_dict_is_a_copy(limits: VelocityLimits) -> None:
    copied = limits.as_dict()
    copied["waist"] = 99.0
    assert limits.get("waist") == 0.5


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_limits_refuse_non_finite(limits: VelocityLimits, value: float) -> None:
    with pytest.raises(CommandError, match=rf"^waist: maximum must be finite, got {value!r}$"):
        limits.set("waist", value)
    assert limits.get("waist") == 0.5


def test_limits_refuse_unknown_channel(limits: VelocityLimits) -> None:
    with pytest.raises(CommandError, match=r"^unknown velocity channel 'tail'$"):
        limits.set("tail", 0.1)


# --- Command ------------------------------------------------------------------------------


def test_a_channel_the_profile_lacks_is_refused_on_the_way_to_the_wire() -> None:
    mapper = CommandMapper(load_profile())
    with pytest.raises(CommandError, match=r"^unknown velocity channels \['tail'\]$"):
        mapper.to_packet(Command(velocities={"tail": 0.1}))
    with pytest.raises(CommandError, match=r"^unknown velocity channels \['tail'\]$"):
        mapper.to_packet(Command().with_velocities({"waist": 0.1, "tail": 0.1}))


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_command_refuses_non_finite(value: float) -> None:
    message = rf"^drive_linear: velocity must be finite, got {value!r}$"
    with pytest.raises(CommandError, match=message):
        Command(velocities={"drive_linear": value})
    with pytest.raises(CommandError, match=message):
        Command().with_velocity("drive_linear", value)


def test_command_helpers() -> None:
    command = Command(torch=True, camera=2).with_velocity("waist", 0.3)
    assert command.velocity("waist") == 0.3
    assert command.velocity("elbow") == 0.0
    assert command.is_motion
    stopped = command.stopped()
    assert not stopped.is_motion
    assert (stopped.torch, stopped.camera) == (True, 2)
    assert not Command(velocities={"waist": 0.0}).is_motion
    both = command.with_velocities({"elbow": -0.1, "waist": 0.0})
    assert (both.velocity("elbow"), both.velocity("waist")) == (-0.1, 0.0)


# --- buttons ------------------------------------------------------------------------------


def test_torch_is_a_button_level() -> None:
    on = MAPPER.to_packet(Command(torch=True))
    assert on.buttons[PROFILE.torch_button] == 1
    assert sum(on.buttons) == 1
    assert MAPPER.to_packet(Command(torch=False)).buttons == (0,) * 16


@pytest.mark.parametrize(("camera", "level"), [(None, 0), (0, 1), (1, 2), (3, 4)])
def test_camera_selector_button(camera: int | None, level: int) -> None:
    packet = MAPPER.to_packet(Command(camera=camera))
    assert packet.buttons[PROFILE.camera_button] == level
    assert sum(packet.buttons) == level
    assert MAPPER.to_command(packet).camera == camera


def test_video_bitrate_passes_through() -> None:
    packet = MAPPER.to_packet(Command(video_bitrate=PROFILE.link.default_video_bitrate))
    assert packet.video_bitrate == 1_000_000.0
    assert MAPPER.to_command(packet).video_bitrate == 1_000_000.0


def test_to_command_reads_any_nonzero_torch_level() -> None:
    buttons = [0] * 16
    buttons[PROFILE.torch_button] = 7
    assert MAPPER.to_command(RemoteControlPacket(buttons=tuple(buttons))).torch


# --- to_command inverts to_packet ---------------------------------------------------------

velocities = st.fixed_dictionaries(
    {
        name: st.floats(-channel.hard_max, channel.hard_max)
        for name, channel in PROFILE.channels.items()
    }
)
commands = st.builds(
    Command,
    velocities=velocities,
    torch=st.booleans(),
    camera=st.none() | st.integers(0, len(PROFILE.link.camera_names) - 1),
    video_bitrate=st.floats(0.0, 1e8),
)


@given(commands)
def test_to_command_inverts_to_packet(command: Command) -> None:
    packet = MAPPER.to_packet(command)
    back = MAPPER.to_command(packet)
    for name, channel in PROFILE.channels.items():
        assert abs(back.velocity(name) - command.velocity(name)) <= 1.0 / channel.axis_per_unit
    assert (back.torch, back.camera, back.video_bitrate) == (
        command.torch,
        command.camera,
        command.video_bitrate,
    )
    assert MAPPER.to_packet(back) == packet


@given(commands)
def test_to_command_inverts_to_packet_with_limits(command: Command) -> None:
    limits = VelocityLimits(PROFILE)
    back = MAPPER.to_command(MAPPER.to_packet(command, limits))
    for name, channel in PROFILE.channels.items():
        expected = limits.clamp(name, command.velocity(name))
        assert abs(back.velocity(name) - expected) <= 1.0 / channel.axis_per_unit


# --- telemetry to SI ----------------------------------------------------------------------


def test_ticks_at_the_zero_offset_are_zero_rad() -> None:
    waist = _waist()
    assert waist.zero_offset_ticks == 2147483648
    assert ticks_to_rad(waist, 2147483648) == 0.0
    assert rad_to_ticks(waist, 0.0) == 2147483648


def test_ticks_per_rad() -> None:
    waist = _waist()
    quarter = 2147483648 + round(math.pi / 2 * 10430.378)
    assert rad_to_ticks(waist, math.pi / 2) == quarter
    assert ticks_to_rad(waist, quarter) == pytest.approx(math.pi / 2, abs=1e-4)


def test_rad_to_ticks_clips_to_u32() -> None:
    waist = _waist()
    assert rad_to_ticks(waist, 1e9) == 2**32 - 1
    assert rad_to_ticks(waist, -1e9) == 0


@given(st.integers(0, 2**32 - 1))
def test_ticks_round_trip(ticks: int) -> None:
    waist = _waist()
    assert rad_to_ticks(waist, ticks_to_rad(waist, ticks)) == ticks


@given(st.floats(-2 * math.pi, 2 * math.pi))
def test_rad_round_trip(angle_rad: float) -> None:
    waist = _waist()
    assert waist.ticks_per_rad is not None
    back = ticks_to_rad(waist, rad_to_ticks(waist, angle_rad))
    assert abs(back - angle_rad) <= 0.5 / waist.ticks_per_rad + 1e-12


def _telemetry() -> TelemetryPacket:
    waist = _waist()
    assert waist.ticks_per_rad is not None
    return TelemetryPacket(
        tick=5000,
        motors=(
            MotorRecord(device_id=1, position=123, speed=500, current=-2000),  # left track
            MotorRecord(device_id=200, position=1, speed=1),  # not in the profile
            MotorRecord(
                device_id=waist.device_id,
                state=1,
                mode=2,
                position=waist.zero_offset_ticks + round(0.5 * waist.ticks_per_rad),
                speed=1000,
                current=1500,
                status=0x0102,
                position_command=waist.zero_offset_ticks,
                speed_command=-250,
                current_command=3000,
            ),
        ),
    )


def test_read_telemetry() -> None:
    readings = read_telemetry(PROFILE, _telemetry())
    assert set(readings) == {"left_track", "waist"}
    speed_scale = PROFILE.telemetry_speed_per_rad_s
    current_scale = PROFILE.telemetry_current_per_amp

    track = readings["left_track"]
    assert track.device_id == 1
    assert track.angle_rad is None
    assert track.target_angle_rad is None
    assert track.speed_rad_s == 500 / speed_scale
    assert track.current_a == -2000 / current_scale

    waist = readings["waist"]
    assert waist.device_id == _waist().device_id
    assert (waist.state, waist.mode, waist.status) == (1, 2, 0x0102)
    assert waist.angle_rad == pytest.approx(0.5, abs=1e-4)
    assert waist.target_angle_rad == 0.0
    assert waist.speed_rad_s == 1000 / speed_scale
    assert waist.current_a == 1500 / current_scale
    assert waist.speed_command_rad_s == -250 / speed_scale
    assert waist.current_command_a == 3000 / current_scale


def test_assumed_telemetry_units() -> None:
    # Assumption (docs/protocol.md): telemetry speed in mrad/s and current in mA.
    readings = read_telemetry(PROFILE, _telemetry())
    assert readings["waist"].speed_rad_s == 1.0
    assert readings["waist"].current_a == 1.5


def test_unknown_device_is_skipped() -> None:
    assert read_motor(PROFILE, MotorRecord(device_id=200)) is None
    assert read_telemetry(PROFILE, TelemetryPacket(motors=(MotorRecord(device_id=200),))) == {}
    assert read_telemetry(PROFILE, TelemetryPacket()) == {}


def test_a_channel_the_robot_moves_backwards_gets_its_axis_negated() -> None:
    data = load_profile_data()
    data["channels"]["shoulder"]["axis_sign"] = -1
    data["channels"]["shoulder"]["axis_per_unit"] = 25_000.0
    mapper = CommandMapper(parse_profile(data))
    axis = PROFILE.channels["shoulder"].axis
    packet = mapper.to_packet(Command({"shoulder": 0.4, "elbow": 0.4}))
    assert packet.axes[axis] == -10_000
    assert _axis(packet, "elbow") == 8_000  # the others keep the sign and the shared scale
    back = mapper.to_command(packet)
    assert back.velocities["shoulder"] == pytest.approx(0.4)
    assert back.velocities["elbow"] == pytest.approx(0.4)
