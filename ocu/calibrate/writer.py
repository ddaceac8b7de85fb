"""The calibrated profile: the base profile's document with the measured keys replaced.

Each measured key gets a `[measured."key"]` table (how, when, residual, samples) and leaves
the `assumptions` list: an entry with a wildcard that covered it is spelled out for the keys
still assumed. Every other key keeps its provenance. The file is written atomically and
only if it loads (`ocu.profile.write_profile_data`).
"""

from __future__ import annotations

import copy
import datetime as dt
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from ocu.calibrate.session import CalibrationResult, Measured
from ocu.profile import AXIS_MAX, assumption_covers, write_profile_data


def calibrated_data(
    base: Mapping[str, Any], result: CalibrationResult, when: dt.datetime | None = None
) -> dict[str, Any]:
    """The base profile document with what the calibration measured."""
    data = copy.deepcopy(dict(base))
    stamp = (when or result.started_at).replace(microsecond=0)
    measured: dict[str, Any] = dict(data.get("measured", {}))
    items = list(result.measured.values())
    # A device ID that moved to another motor frees its old owner's: swap, not duplicate.
    _swap_device_ids(data, [m for m in items if m.key.endswith(".device_id")])
    for item in items:
        if not item.key.endswith(".device_id"):
            _set(data, item.key, item.value)
        measured[item.key] = _entry(item, stamp)
    for item in _bounded_maxima(data, result):
        measured[item.key] = _entry(item, stamp)
    data["measured"] = measured
    data["assumptions"] = _remaining_assumptions(data, data.get("assumptions", []), measured)
    return data


def write_calibrated_profile(
    path: str | Path,
    base: Mapping[str, Any],
    result: CalibrationResult,
    *,
    robot: str,
    base_name: str,
) -> dict[str, Any]:
    """Write the calibrated profile atomically; returns the document written."""
    data = calibrated_data(base, result)
    stamp = result.started_at.replace(microsecond=0).isoformat()
    header = (
        f"Robot profile written by `ocu calibrate` for {robot} on {stamp},\n"
        f'from {base_name}. Keys under [measured."..."] were measured on the robot (how, when,\n'
        "with what residual); keys in `assumptions` are still guesses; all others come from\n"
        "the documents (docs/protocol.md, docs/calibration.md)."
    )
    write_profile_data(path, data, header)
    return data


def _entry(item: Measured, when: dt.datetime) -> dict[str, Any]:
    entry: dict[str, Any] = {"how": item.how, "when": when}
    if item.residual is not None:
        entry["residual"] = float(item.residual)
    if item.residual_unit is not None:
        entry["residual_unit"] = item.residual_unit
    if item.samples is not None:
        entry["samples"] = int(item.samples)
    return entry


def _set(data: dict[str, Any], key: str, value: Any) -> None:
    *tables, leaf = key.split(".")
    table = data
    for part in tables:
        table = table.setdefault(part, {})
    table[leaf] = value


def _swap_device_ids(data: dict[str, Any], items: Iterable[Measured]) -> None:
    motors: dict[str, dict[str, Any]] = data["motors"]
    for item in items:
        name = item.key.split(".")[1]
        new_id = item.value
        old_id = motors[name]["device_id"]
        for other_name, other in motors.items():
            if other_name != name and other["device_id"] == new_id:
                other["device_id"] = old_id
        motors[name]["device_id"] = new_id


SCALE_KEYS = {
    "linear": "si.linear_axis_per_m_s",
    "rotation": "si.rotation_axis_per_rad_s",
    "joint": "si.joint_axis_per_rad_s",
}


def _bounded_maxima(data: dict[str, Any], result: CalibrationResult) -> list[Measured]:
    """Maxima a measured axis scale (the channel's own or its SI scale) can no longer carry
    in the int16 axis, lowered."""
    lowered: list[Measured] = []
    for name, channel in data["channels"].items():
        own = f"channels.{name}.axis_per_unit"
        if "axis_per_unit" in channel:
            measured, per_unit = own in result.measured, float(channel["axis_per_unit"])
        else:
            key = SCALE_KEYS.get(channel.get("scale", ""), "")
            if not key:
                continue
            measured = key in result.measured
            per_unit = float(data["si"][key.split(".")[1]])
        if not measured:
            continue
        limit = AXIS_MAX / per_unit
        if channel["hard_max"] <= limit:
            continue
        channel["hard_max"] = int(limit * 1000) / 1000
        channel["default_max"] = min(channel["default_max"], channel["hard_max"])
        channel["min_speed"] = min(channel["min_speed"], channel["default_max"])
        lowered.append(
            Measured(
                f"channels.{name}.hard_max",
                channel["hard_max"],
                f"lowered so the measured axis scale ({per_unit:g} per unit) fits the int16 "
                f"axis ({AXIS_MAX})",
            )
        )
    return lowered


def _leaves(data: Mapping[str, Any], prefix: str = "") -> list[str]:
    keys: list[str] = []
    for key, value in data.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            keys += _leaves(value, f"{name}.")
        else:
            keys.append(name)
    return keys


def _remaining_assumptions(
    data: Mapping[str, Any], assumptions: Iterable[str], measured: Mapping[str, Any]
) -> list[str]:
    """The assumptions list without the measured keys; wildcards spelled out where needed."""
    leaves = [key for key in _leaves(data) if not key.startswith("measured.")]
    remaining: list[str] = []
    for pattern in assumptions:
        if pattern in measured:
            continue
        if not any(assumption_covers(pattern, key) for key in measured):
            remaining.append(pattern)
            continue
        remaining += [
            key
            for key in leaves
            if assumption_covers(pattern, key) and key not in measured and key not in remaining
        ]
    return remaining
