"""The realtime interface (port 30003): one packet per controller period, its layout by
controller version (docs/ur.md)."""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field

from ocu.protocol.ur.common import RobotMode, SafetyMode, UrProtocolError, Vector3, Vector6

# ---- realtime (30003) ------------------------------------------------------------------------

LENGTH_FIELD = struct.Struct(">i")

#: The realtime packet's fields in wire order after the length: (name, doubles). Each controller
#: version sends a prefix of this list (REALTIME_SIZES); "unused_*" are "used by Universal
#: Robots software only" and kept as they came so that a packet round-trips byte for byte.
REALTIME_FIELDS: tuple[tuple[str, int], ...] = (
    ("time_s", 1),
    ("q_target", 6),
    ("qd_target", 6),
    ("qdd_target", 6),
    ("i_target", 6),
    ("m_target", 6),
    ("q_actual", 6),
    ("qd_actual", 6),
    ("i_actual", 6),
    ("i_control", 6),
    ("tool_vector_actual", 6),
    ("tcp_speed_actual", 6),
    ("tcp_force", 6),
    ("tool_vector_target", 6),
    ("tcp_speed_target", 6),
    ("digital_input_bits", 1),
    ("motor_temperatures", 6),
    ("controller_timer_s", 1),
    ("unused_test_value", 1),
    ("robot_mode", 1),
    ("joint_modes", 6),
    ("safety_mode", 1),
    ("unused_1", 6),
    ("tool_accelerometer", 3),
    ("unused_2", 6),
    ("speed_scaling", 1),
    ("linear_momentum_norm", 1),
    ("unused_3", 1),
    ("unused_4", 1),
    ("v_main", 1),
    ("v_robot", 1),
    ("i_robot", 1),
    ("v_actual", 6),
    # 1044 bytes end here (3.0-3.1)
    ("digital_outputs", 1),
    ("program_state", 1),
    # 1060 (3.2-3.4)
    ("elbow_position", 3),
    ("elbow_velocity", 3),
    # 1108 (3.5-3.9, 5.0-5.3)
    ("safety_status", 1),
    # 1116 (3.10-3.13, 5.4-5.8)
    ("unused_5", 1),
    ("unused_6", 1),
    ("unused_7", 1),
    # 1140 (3.14-3.15, 5.9)
    ("payload_mass_kg", 1),
    ("payload_cog", 3),
    ("payload_inertia", 6),
    # 1220 (5.10 and later)
)

#: Packet size (bytes, the length field included) per controller version range: the first
#: whose (major, minor) bound is not above the version.
REALTIME_SIZES: tuple[tuple[tuple[int, int], tuple[int, int], int], ...] = (
    ((3, 0), (3, 1), 1044),
    ((3, 2), (3, 4), 1060),
    ((3, 5), (3, 9), 1108),
    ((3, 10), (3, 13), 1116),
    ((3, 14), (3, 99), 1140),
    ((5, 0), (5, 3), 1108),
    ((5, 4), (5, 8), 1116),
    ((5, 9), (5, 9), 1140),
    ((5, 10), (5, 99), 1220),
)
KNOWN_REALTIME_SIZES = frozenset(size for _, _, size in REALTIME_SIZES)


def realtime_size(version: tuple[int, int]) -> int:
    """The realtime packet's size for a controller version (major, minor)."""
    for low, high, size in REALTIME_SIZES:
        if low <= version[:2] <= high:
            return size
    raise UrProtocolError(
        f"no known realtime layout for controller version {version[0]}.{version[1]}"
    )


def _field_counts(size: int) -> tuple[tuple[str, int], ...]:
    doubles = (size - LENGTH_FIELD.size) // 8
    fields: list[tuple[str, int]] = []
    total = 0
    for name, count in REALTIME_FIELDS:
        if total + count > doubles:
            break
        fields.append((name, count))
        total += count
    if total != doubles:
        raise AssertionError(f"realtime size {size} does not end on a field boundary")
    return tuple(fields)


_REALTIME_LAYOUTS: dict[int, tuple[struct.Struct, tuple[tuple[str, int], ...]]] = {
    size: (struct.Struct(f">i{(size - 4) // 8}d"), _field_counts(size))
    for size in sorted(KNOWN_REALTIME_SIZES)
}

#: The fields that every layout has; the others are None where the version lacks them.
_OPTIONAL_FIELDS = {name for name, _ in REALTIME_FIELDS} - {
    name for name, _ in _REALTIME_LAYOUTS[1044][1]
}


def _whole(value: float, what: str, low: int, high: int) -> int:
    if not math.isfinite(value) or value != int(value) or not low <= value <= high:
        raise UrProtocolError(f"{what} {value!r} is not a whole number in [{low}, {high}]")
    return int(value)


@dataclass(frozen=True)
class RealtimeState:
    """One realtime packet (SI units: rad, rad/s, A, m, s; pose = x, y, z, rotation vector).

    `size` is the layout (the packet's length); fields the layout lacks are None.
    """

    size: int
    time_s: float
    q_target: Vector6
    qd_target: Vector6
    qdd_target: Vector6
    i_target: Vector6
    m_target: Vector6
    q_actual: Vector6
    qd_actual: Vector6
    i_actual: Vector6
    i_control: Vector6
    tool_vector_actual: Vector6
    tcp_speed_actual: Vector6
    tcp_force: Vector6
    tool_vector_target: Vector6
    tcp_speed_target: Vector6
    digital_input_bits: float
    motor_temperatures: Vector6
    controller_timer_s: float
    robot_mode: float
    joint_modes: Vector6
    safety_mode: float
    tool_accelerometer: Vector3
    speed_scaling: float
    linear_momentum_norm: float
    v_main: float
    v_robot: float
    i_robot: float
    v_actual: Vector6
    digital_outputs: float | None = None
    program_state: float | None = None
    elbow_position: Vector3 | None = None
    elbow_velocity: Vector3 | None = None
    safety_status: float | None = None
    payload_mass_kg: float | None = None
    payload_cog: Vector3 | None = None
    payload_inertia: Vector6 | None = None
    #: The "used by Universal Robots software only" values, in wire order.
    unused: tuple[float, ...] = field(default=(), repr=False)

    def __post_init__(self) -> None:
        if self.size not in _REALTIME_LAYOUTS:
            raise UrProtocolError(f"unknown realtime packet size {self.size}")
        _whole(self.robot_mode, "robot mode", -1, 8)
        _whole(self.safety_mode, "safety mode", 1, 22)

    @property
    def mode(self) -> RobotMode:
        """The robot mode as an enum."""
        return RobotMode(int(self.robot_mode))

    @property
    def safety(self) -> SafetyMode:
        """The safety mode as an enum (SafetyMode has gaps: 21 reads as UNDEFINED)."""
        value = int(self.safety_mode)
        return SafetyMode(value) if value in SafetyMode._value2member_map_ else SafetyMode(11)

    @classmethod
    def decode(cls, data: bytes, *, expected_size: int | None = None) -> RealtimeState:
        """Parse one whole realtime packet; UrProtocolError for anything malformed."""
        if len(data) < LENGTH_FIELD.size:
            raise UrProtocolError(f"realtime packet of {len(data)} bytes: no length field")
        (length,) = LENGTH_FIELD.unpack_from(data)
        if length != len(data):
            raise UrProtocolError(f"realtime length field says {length} bytes, got {len(data)}")
        if expected_size is not None and length != expected_size:
            raise UrProtocolError(
                f"realtime packet of {length} bytes, expected {expected_size} for this controller"
            )
        layout = _REALTIME_LAYOUTS.get(length)
        if layout is None:
            raise UrProtocolError(
                f"realtime packet of {length} bytes matches no known layout "
                f"({', '.join(map(str, sorted(KNOWN_REALTIME_SIZES)))})"
            )
        codec, fields = layout
        values = codec.unpack(data)[1:]
        kwargs: dict[str, object] = {"size": length}
        unused: list[float] = []
        index = 0
        for name, count in fields:
            chunk = values[index : index + count]
            index += count
            if name.startswith("unused"):
                unused.extend(chunk)
            else:
                kwargs[name] = chunk[0] if count == 1 else tuple(chunk)
        kwargs["unused"] = tuple(unused)
        return cls(**kwargs)  # type: ignore[arg-type]

    def encode(self) -> bytes:
        """The packet's bytes in its layout (`size`)."""
        codec, fields = _REALTIME_LAYOUTS[self.size]
        values: list[float] = []
        unused = list(self.unused)
        for name, count in fields:
            if name.startswith("unused"):
                taken, unused = unused[:count], unused[count:]
                values.extend(taken + [0.0] * (count - len(taken)))
                continue
            value = getattr(self, name)
            if value is None:
                raise UrProtocolError(f"{name} is required in the {self.size}-byte layout")
            if count == 1:
                values.append(float(value))
            else:
                if len(value) != count:
                    raise UrProtocolError(f"{name} has {len(value)} values, expected {count}")
                values.extend(float(v) for v in value)
        return codec.pack(self.size, *values)


def realtime_state(size: int, **values: object) -> RealtimeState:
    """A RealtimeState for layout `size` with every field it has defaulted to zeros."""
    _, fields = _REALTIME_LAYOUTS.get(size, (None, ()))
    if not fields:
        raise UrProtocolError(f"unknown realtime packet size {size}")
    present = {name for name, _ in fields}
    defaults: dict[str, object] = {"size": size, "robot_mode": 7.0, "safety_mode": 1.0}
    defaults["unused"] = (0.0,) * sum(n for name, n in fields if name.startswith("unused"))
    for name, count in fields:
        if not name.startswith("unused") and name not in defaults:
            defaults[name] = 0.0 if count == 1 else (0.0,) * count
    for name in values:
        if name not in present and name in _OPTIONAL_FIELDS:
            raise UrProtocolError(f"{name} is not in the {size}-byte layout")
    defaults.update(values)
    return RealtimeState(**defaults)  # type: ignore[arg-type]
