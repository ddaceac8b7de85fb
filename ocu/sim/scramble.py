"""An unknown robot for the simulator to play: a profile's wire facts shuffled by a seed.

`ocu-sim --scramble SEED` runs the simulator on a profile in which every fact a calibration
must find has been changed: the channels sit on other RCP axes (any of the 16), some move the
other way (`axis_sign`), each joint has its own axis scale and ticks per radian (within ±50 %
of the profile's) and a zero offset anywhere in the u32 range, and the drive constants differ
from the documents' by up to ±20 % (measured on another robot). With `--scramble-ids` the
device IDs of the motors that report a position are shuffled too, so the device ID -> joint
map must be found by an operator (ocu calibrate's guided mode). The track motors keep their
IDs: which track is left cannot be told from the telemetry either. `--scramble-out` writes
the hidden truth as a profile file, for tests to compare with what `ocu calibrate` found.
"""

from __future__ import annotations

import copy
import math
import random
from typing import Any

from ocu.profile import AXIS_COUNT, AXIS_MAX, write_profile_data

SCALE_SPREAD = 0.5  # joint scales and ticks per radian are drawn within ±50 %
DRIVE_SPREAD = 0.2  # the drive constants within ±20 %
DRIVE_CONSTANTS = ("linear_axis_per_m_s", "rotation_axis_per_rad_s")
U32_MAX = 2**32 - 1
# Room kept between a zero offset and the ends of the u32 range, beyond the joint's limits.
OFFSET_MARGIN_RAD = 0.5


def scramble_profile_data(data: dict[str, Any], seed: int, *, ids: bool = False) -> dict[str, Any]:
    """A copy of a profile document with axes, signs, scales, ticks and offsets redrawn."""
    rng = random.Random(seed)
    out = copy.deepcopy(data)
    si = out["si"]
    # The documents' drive constants were measured on one robot: another may differ a little.
    for key in DRIVE_CONSTANTS:
        si[key] = round(float(si[key]) * rng.uniform(1 - DRIVE_SPREAD, 1 + DRIVE_SPREAD), 3)
    scales = {
        "linear": float(si["linear_axis_per_m_s"]),
        "rotation": float(si["rotation_axis_per_rad_s"]),
        "joint": float(si["joint_axis_per_rad_s"]),
    }
    channels: dict[str, dict[str, Any]] = out["channels"]
    new_axes = rng.sample(range(AXIS_COUNT), len(channels))
    for channel, axis in zip(channels.values(), new_axes, strict=True):
        channel["axis"] = axis
        channel["axis_sign"] = rng.choice((1, -1))
        per_unit = scales[channel["scale"]]
        if channel["scale"] == "joint":
            per_unit = round(per_unit * rng.uniform(1 - SCALE_SPREAD, 1 + SCALE_SPREAD), 3)
            channel["axis_per_unit"] = per_unit
        # A hard maximum the int16 axis can no longer carry is lowered with the scale.
        limit = AXIS_MAX / per_unit
        if channel["hard_max"] > limit:
            channel["hard_max"] = math.floor(limit * 1000) / 1000
            channel["default_max"] = min(channel["default_max"], channel["hard_max"])
    motors: dict[str, dict[str, Any]] = out["motors"]
    positioned = [name for name, motor in motors.items() if "ticks_per_rad" in motor]
    for name in positioned:
        motor = motors[name]
        ticks = float(motor["ticks_per_rad"]) * rng.uniform(1 - SCALE_SPREAD, 1 + SCALE_SPREAD)
        motor["ticks_per_rad"] = round(ticks, 3)
        low_deg, high_deg = motor.get("limits_deg", (-180.0, 180.0))
        reach = max(abs(low_deg), abs(high_deg))
        margin = math.ceil((math.radians(reach) + OFFSET_MARGIN_RAD) * motor["ticks_per_rad"])
        motor["zero_offset_ticks"] = rng.randint(margin, U32_MAX - margin)
    if ids:
        shuffled = [motors[name]["device_id"] for name in positioned]
        while len(shuffled) > 1 and shuffled == [motors[n]["device_id"] for n in positioned]:
            rng.shuffle(shuffled)
        for name, device_id in zip(positioned, shuffled, strict=True):
            motors[name]["device_id"] = device_id
    return out


def write_truth(path: str, data: dict[str, Any], seed: int, ids: bool) -> None:
    """Write the scrambled profile (the hidden truth) atomically."""
    flag = " --scramble-ids" if ids else ""
    write_profile_data(
        path,
        data,
        header=f"The hidden truth of `ocu-sim --scramble {seed}{flag}`: the robot the "
        "simulator plays.\nNot for the OCU: `ocu calibrate` must find these values.",
    )
