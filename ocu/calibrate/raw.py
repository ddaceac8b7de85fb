"""Raw access for calibration: a profile whose channels are the 16 bare RCP axes.

A calibration must command axes the profile may not know (which axis drives the shoulder is
what it is looking for), so it talks to the robot through a `Link` built on
`raw_profile(profile)`: channel `axis<k>` carries RCP axis k, one unit per axis step, with the
profile's motors (without their channels) for decoding. Everything else (frame types,
timing, e-stop repeats) is the profile's.
"""

from __future__ import annotations

from dataclasses import replace

from ocu.profile import AXIS_COUNT, AXIS_MAX, Channel, RobotProfile
from ocu.records import Command

U32 = 2**32


def axis_channel(axis: int) -> str:
    """The raw profile's channel that carries one RCP axis."""
    return f"axis{axis}"


def raw_profile(profile: RobotProfile) -> RobotProfile:
    """The profile with its channels replaced by the 16 raw axes (see the module docstring)."""
    channels = {
        axis_channel(axis): Channel(
            name=axis_channel(axis),
            axis=axis,
            axis_per_unit=1.0,
            unit="axis",
            min_speed=0.0,
            default_max=float(AXIS_MAX),
            hard_max=float(AXIS_MAX),
        )
        for axis in range(AXIS_COUNT)
    }
    # The motors keep their device IDs and position scales but drive no channel here.
    motors = {name: replace(motor, channel=None) for name, motor in profile.motors.items()}
    return replace(profile, channels=channels, motors=motors, extension=None)


def raw_command(profile: RobotProfile, axes: dict[int, int] | None = None) -> Command:
    """A command of raw axis values (none: all zero), with the profile's video bit-rate."""
    velocities = {axis_channel(axis): float(value) for axis, value in (axes or {}).items()}
    return Command(velocities=velocities, video_bitrate=profile.link.default_video_bitrate)


def tick_delta(before: int, after: int) -> int:
    """Signed difference of two u32 positions, across a wrap of the counter."""
    delta = (after - before) % U32
    return delta - U32 if delta >= U32 // 2 else delta
