"""The Engineer's wire in SI units: commands to RCP axes and buttons, packets to records.

The one place where the vendor protocol's packets meet the neutral records (ocu.records): the
links (ocu.link), the simulator, the recorder and `ocu calibrate` call it; nothing above the
links imports it (pyproject.toml's import-linter contracts).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Protocol

from ocu.profile import AXIS_MAX, Motor, RobotProfile
from ocu.protocol.extended import SCAN_INVALID, SCAN_NO_RETURN, ScanPacket
from ocu.protocol.packets import (
    AXIS_COUNT,
    BUTTON_COUNT,
    MotorRecord,
    RemoteControlPacket,
    TelemetryPacket,
)
from ocu.records import SCAN_FROM_ROBOT, Command, CommandError, JointReading, ScanFrame

_I16_MAX = 32767


class Clamp(Protocol):
    """The operator's velocity limits (ocu.control.commands.VelocityLimits)."""

    def clamp(self, channel: str, value: float) -> float:
        """A velocity bounded by the channel's current maximum, sign kept."""
        ...


def _to_axis(value: float, per_unit: float) -> int:
    return int(min(max(round(value * per_unit), -AXIS_MAX), AXIS_MAX))


class CommandMapper:
    """Turns SI commands into RCPs and RCPs back into SI (the simulator's side)."""

    def __init__(self, profile: RobotProfile) -> None:
        self.profile = profile

    def to_packet(self, command: Command, limits: Clamp | None = None) -> RemoteControlPacket:
        """The RCP for a command, each velocity clamped to the limits (hard max if None)."""
        unknown = set(command.velocities) - set(self.profile.channels)
        if unknown:
            raise CommandError(f"unknown velocity channels {sorted(unknown)}")
        axes = [0] * AXIS_COUNT
        for name, channel in self.profile.channels.items():
            value = command.velocity(name)
            if limits is not None:
                value = limits.clamp(name, value)
            value = min(max(value, -channel.hard_max), channel.hard_max)
            # A channel the robot moves backwards (axis_sign -1) gets its axis negated.
            axes[channel.axis] = _to_axis(value * channel.axis_sign, channel.axis_per_unit)
        buttons = [0] * BUTTON_COUNT
        buttons[self.profile.torch_button] = 1 if command.torch else 0
        if command.camera is not None:
            buttons[self.profile.camera_button] = command.camera + 1
        return RemoteControlPacket(
            axes=tuple(axes), buttons=tuple(buttons), video_bitrate=command.video_bitrate
        )

    def to_command(self, packet: RemoteControlPacket) -> Command:
        """The SI command an RCP carries (inverse of to_packet up to axis rounding)."""
        velocities = {
            name: packet.axes[ch.axis] * ch.axis_sign / ch.axis_per_unit
            for name, ch in self.profile.channels.items()
            if packet.axes[ch.axis] != 0
        }
        selector = packet.buttons[self.profile.camera_button]
        return Command(
            velocities=velocities,
            torch=packet.buttons[self.profile.torch_button] != 0,
            camera=selector - 1 if selector > 0 else None,
            video_bitrate=packet.video_bitrate,
        )


def ticks_to_rad(motor: Motor, ticks: int) -> float:
    """Raw u32 position to radians about the motor's zero."""
    assert motor.ticks_per_rad is not None
    return (ticks - motor.zero_offset_ticks) / motor.ticks_per_rad


def rad_to_ticks(motor: Motor, angle_rad: float) -> int:
    """Radians to the raw u32 position, clipped to the u32 range."""
    assert motor.ticks_per_rad is not None
    raw = round(angle_rad * motor.ticks_per_rad) + motor.zero_offset_ticks
    return int(min(max(raw, 0), 2**32 - 1))


def read_motor(profile: RobotProfile, record: MotorRecord) -> JointReading | None:
    """SI reading of one motor record, or None for a device the profile does not know."""
    motor = profile.motor_by_device(record.device_id)
    if motor is None:
        return None
    speed_scale = profile.telemetry_speed_per_rad_s
    current_scale = profile.telemetry_current_per_amp
    positioned = motor.has_position
    return JointReading(
        name=motor.name,
        device_id=record.device_id,
        state=record.state,
        mode=record.mode,
        angle_rad=ticks_to_rad(motor, record.position) if positioned else None,
        speed_rad_s=record.speed / speed_scale,
        current_a=record.current / current_scale,
        status=record.status,
        target_angle_rad=ticks_to_rad(motor, record.position_command) if positioned else None,
        speed_command_rad_s=record.speed_command / speed_scale,
        current_command_a=record.current_command / current_scale,
    )


def read_telemetry(profile: RobotProfile, packet: TelemetryPacket) -> dict[str, JointReading]:
    """SI readings of every known motor in a telemetry packet, by joint name."""
    readings: dict[str, JointReading] = {}
    for record in packet.motors:
        reading = read_motor(profile, record)
        if reading is not None:
            readings[reading.name] = reading
    return readings


def track_speeds(profile: RobotProfile, velocities: Mapping[str, float]) -> tuple[float, float]:
    """Left and right belt speeds (m/s) of a drive command (differential drive)."""
    drive = profile.drive_channels
    if drive is None:
        return 0.0, 0.0
    linear_m_s = velocities.get(drive[0], 0.0)
    turn_rad_s = velocities.get(drive[1], 0.0)
    half_width_m = profile.track_width_m / 2.0
    return (linear_m_s - turn_rad_s * half_width_m, linear_m_s + turn_rad_s * half_width_m)


def speed_to_raw(profile: RobotProfile, speed: float) -> int:
    """A speed (rad/s, or m/s for a track) in the telemetry's i16 units."""
    raw = round(speed * profile.telemetry_speed_per_rad_s)
    return int(min(max(raw, -_I16_MAX - 1), _I16_MAX))


def commanded_motor_speeds(profile: RobotProfile, command: Command) -> dict[int, int]:
    """Device ID to the speed command each motor reports while it runs `command` (raw).

    The link compares these with the echo in telemetry to measure its delay
    (ocu.link.delay); the simulator reports exactly these.
    """
    left, right = track_speeds(profile, command.velocities)
    speeds: dict[int, int] = {}
    for motor in profile.motors.values():
        if motor.track is not None:
            belt_m_s = left if motor.track == "left" else right
            speeds[motor.device_id] = speed_to_raw(profile, belt_m_s)
        elif motor.channel is not None:
            speeds[motor.device_id] = speed_to_raw(profile, command.velocity(motor.channel))
    return speeds


def scan_frame(packet: ScanPacket, received_at: float, wall_time: float) -> ScanFrame:
    """The scan a robot sent, in metres and radians."""
    ranges = tuple(
        math.inf if raw == SCAN_NO_RETURN else math.nan if raw == SCAN_INVALID else raw / 1e3
        for raw in packet.ranges_mm
    )
    return ScanFrame(
        angle_min_rad=packet.angle_min_urad / 1e6,
        angle_increment_rad=packet.angle_increment_urad / 1e6,
        range_min_m=packet.range_min_mm / 1e3,
        range_max_m=packet.range_max_mm / 1e3,
        ranges_m=ranges,
        received_at=received_at,
        wall_time=wall_time,
        source=SCAN_FROM_ROBOT,
        sequence=packet.sequence,
        capture_time_us=packet.capture_time_us,
    )
