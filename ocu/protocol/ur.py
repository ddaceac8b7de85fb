"""Universal Robots controller codecs: the realtime (30003) and primary/secondary (30001/30002)
packets, URScript motion commands, and a TCP stream splitter. Pure: no sockets, no threads.

Every layout and its source is in docs/ur.md. Numbers are big-endian (network order) on every
UR port. All three ports carry framed packets whose first four bytes are the packet's length,
header included; the primary/secondary packets then have a one-byte type.
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from enum import IntEnum

from ocu.protocol.errors import ProtocolError

JOINTS = 6

Vector6 = tuple[float, float, float, float, float, float]
Vector3 = tuple[float, float, float]


class UrProtocolError(ProtocolError):
    """A UR packet or URScript line that does not follow the controller's wire format."""


class RobotMode(IntEnum):
    """The controller's robot mode (ur_client_library datatypes.h; the realtime doc)."""

    NO_CONTROLLER = -1
    DISCONNECTED = 0
    CONFIRM_SAFETY = 1
    BOOTING = 2
    POWER_OFF = 3
    POWER_ON = 4
    IDLE = 5
    BACKDRIVE = 6
    RUNNING = 7
    UPDATING_FIRMWARE = 8


class SafetyMode(IntEnum):
    """The controller's safety mode (ur_client_library datatypes.h, 1..22)."""

    NORMAL = 1
    REDUCED = 2
    PROTECTIVE_STOP = 3
    RECOVERY = 4
    SAFEGUARD_STOP = 5
    SYSTEM_EMERGENCY_STOP = 6
    ROBOT_EMERGENCY_STOP = 7
    VIOLATION = 8
    FAULT = 9
    VALIDATE_JOINT_ID = 10
    UNDEFINED_SAFETY_MODE = 11
    AUTOMATIC_MODE_SAFEGUARD_STOP = 12
    SYSTEM_THREE_POSITION_ENABLING_STOP = 13
    TP_THREE_POSITION_ENABLING_STOP = 14
    IMMI_EMERGENCY_STOP = 15
    IMMI_SAFEGUARD_STOP = 16
    PROFISAFE_WAITING_FOR_PARAMETERS = 17
    PROFISAFE_AUTOMATIC_MODE_SAFEGUARD_STOP = 18
    PROFISAFE_SAFEGUARD_STOP = 19
    PROFISAFE_EMERGENCY_STOP = 20
    SAFETY_API_SAFEGUARD_STOP = 22


# ---- realtime (30003) ------------------------------------------------------------------------

_LENGTH = struct.Struct(">i")

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
    doubles = (size - _LENGTH.size) // 8
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
        if len(data) < _LENGTH.size:
            raise UrProtocolError(f"realtime packet of {len(data)} bytes: no length field")
        (length,) = _LENGTH.unpack_from(data)
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


# ---- primary / secondary (30001, 30002) ------------------------------------------------------


class PackageType(IntEnum):
    """The primary/secondary packet types (ur_client_library primary/package_header.h)."""

    ROBOT_STATE = 16
    ROBOT_MESSAGE = 20
    HMC_MESSAGE = 22
    MODBUS_INFO_MESSAGE = 5
    SAFETY_SETUP_BROADCAST_MESSAGE = 23
    SAFETY_COMPLIANCE_TOLERANCES_MESSAGE = 24
    PROGRAM_STATE_MESSAGE = 25


class RobotStateType(IntEnum):
    """Sub-packages of a ROBOT_STATE packet (ur_client_library primary/robot_state.h)."""

    ROBOT_MODE_DATA = 0
    JOINT_DATA = 1
    TOOL_DATA = 2
    MASTERBOARD_DATA = 3
    CARTESIAN_INFO = 4
    KINEMATICS_INFO = 5
    CONFIGURATION_DATA = 6
    FORCE_MODE_DATA = 7
    ADDITIONAL_INFO = 8
    CALIBRATION_DATA = 9
    SAFETY_DATA = 10
    TOOL_COMM_INFO = 11
    TOOL_MODE_INFO = 12


ROBOT_MESSAGE_VERSION = 3
MESSAGE_SOURCE_CONTROLLER = -2  # assumed: docs/ur.md

_HEADER = struct.Struct(">iB")  # length (header included), type
_SUB_HEADER = struct.Struct(">IB")
_MESSAGE_HEADER = struct.Struct(">iBQbB")  # length, 20, timestamp, source, message type
_VERSION_NUMBERS = struct.Struct(">BBii")  # major, minor, bugfix (svn), build
#: The largest primary packet accepted; a length above it is a lost frame, not a packet.
MAX_PRIMARY_SIZE = 1 << 16


@dataclass(frozen=True)
class VersionMessage:
    """The controller's first message on 30001 (and on 30002 from 3.1): its software version."""

    project_name: str
    major: int
    minor: int
    bugfix: int
    build: int
    build_date: str = ""
    timestamp_us: int = 0
    source: int = MESSAGE_SOURCE_CONTROLLER

    @property
    def version(self) -> tuple[int, int]:
        """(major, minor)."""
        return (self.major, self.minor)

    def encode(self) -> bytes:
        """The whole packet: header, message header, name, numbers, date."""
        name = self.project_name.encode()
        if len(name) > 127:
            raise UrProtocolError(f"project name of {len(name)} bytes is over 127")
        body = (
            bytes([len(name)])
            + name
            + _VERSION_NUMBERS.pack(self.major, self.minor, self.bugfix, self.build)
            + self.build_date.encode()
        )
        head = _MESSAGE_HEADER.pack(
            _MESSAGE_HEADER.size + len(body),
            PackageType.ROBOT_MESSAGE,
            self.timestamp_us,
            self.source,
            ROBOT_MESSAGE_VERSION,
        )
        return head + body

    @classmethod
    def decode(cls, data: bytes) -> VersionMessage:
        """Parse a whole version-message packet."""
        _check_frame(data, PackageType.ROBOT_MESSAGE)
        if len(data) < _MESSAGE_HEADER.size + 1:
            raise UrProtocolError(f"robot message of {len(data)} bytes has no body")
        _, _, timestamp, source, kind = _MESSAGE_HEADER.unpack_from(data)
        if kind != ROBOT_MESSAGE_VERSION:
            raise UrProtocolError(f"robot message type {kind} is not a version message (3)")
        offset = _MESSAGE_HEADER.size
        name_length = struct.unpack_from(">b", data, offset)[0]
        offset += 1
        if name_length < 0 or offset + name_length + _VERSION_NUMBERS.size > len(data):
            raise UrProtocolError(
                f"version message: project name of {name_length} bytes overruns the packet"
            )
        name = data[offset : offset + name_length]
        offset += name_length
        major, minor, bugfix, build = _VERSION_NUMBERS.unpack_from(data, offset)
        offset += _VERSION_NUMBERS.size
        return cls(
            project_name=name.decode(errors="replace"),
            major=major,
            minor=minor,
            bugfix=bugfix,
            build=build,
            build_date=data[offset:].decode(errors="replace"),
            timestamp_us=timestamp,
            source=source,
        )


def _check_frame(data: bytes, kind: int) -> None:
    if len(data) < _HEADER.size:
        raise UrProtocolError(f"packet of {len(data)} bytes is shorter than its header (5)")
    length, found = _HEADER.unpack_from(data)
    if length != len(data):
        raise UrProtocolError(f"length field says {length} bytes, got {len(data)}")
    if found != kind:
        raise UrProtocolError(f"packet type {found}, expected {kind}")


# Robot mode data: 38 bytes (3.0-3.1), 46 (3.2-3.4, + target speed fraction limit), 47 (3.5+
# and 5.x, + one reserved byte). Sizes from python-urx ursecmon; fields from ur_client_library.
_MODE_38 = struct.Struct(">IBQ???????bBdd")
_MODE_46 = struct.Struct(">IBQ???????bBddd")
_MODE_47 = struct.Struct(">IBQ???????bBdddB")
_MODE_LAYOUTS = {s.size: s for s in (_MODE_38, _MODE_46, _MODE_47)}


@dataclass(frozen=True)
class RobotModeData:
    """Sub-package 0: the robot mode and the stop flags (timestamp in µs)."""

    timestamp_us: int = 0
    real_robot_connected: bool = True
    real_robot_enabled: bool = True
    power_on: bool = True
    emergency_stopped: bool = False
    protective_stopped: bool = False
    program_running: bool = False
    program_paused: bool = False
    robot_mode: int = RobotMode.RUNNING
    control_mode: int = 0
    target_speed_fraction: float = 1.0
    speed_scaling: float = 1.0
    target_speed_fraction_limit: float | None = 1.0
    reserved: int | None = 0

    @property
    def size(self) -> int:
        """The sub-package's length in its layout."""
        if self.target_speed_fraction_limit is None:
            return _MODE_38.size
        return _MODE_46.size if self.reserved is None else _MODE_47.size

    def encode(self) -> bytes:
        """The sub-package with its header."""
        layout = _MODE_LAYOUTS[self.size]
        values: list[object] = [
            layout.size,
            RobotStateType.ROBOT_MODE_DATA,
            self.timestamp_us,
            self.real_robot_connected,
            self.real_robot_enabled,
            self.power_on,
            self.emergency_stopped,
            self.protective_stopped,
            self.program_running,
            self.program_paused,
            self.robot_mode,
            self.control_mode,
            self.target_speed_fraction,
            self.speed_scaling,
        ]
        if self.target_speed_fraction_limit is not None:
            values.append(self.target_speed_fraction_limit)
            if self.reserved is not None:
                values.append(self.reserved)
        return layout.pack(*values)

    @classmethod
    def decode(cls, data: bytes) -> RobotModeData:
        """Parse the sub-package (header included)."""
        layout = _MODE_LAYOUTS.get(len(data))
        if layout is None:
            raise UrProtocolError(f"robot mode data of {len(data)} bytes (known: 38, 46, 47)")
        values = layout.unpack(data)
        mode = values[10]
        if mode not in RobotMode._value2member_map_:
            raise UrProtocolError(f"robot mode {mode} is not a known robot mode (-1..8)")
        return cls(
            timestamp_us=values[2],
            real_robot_connected=values[3],
            real_robot_enabled=values[4],
            power_on=values[5],
            emergency_stopped=values[6],
            protective_stopped=values[7],
            program_running=values[8],
            program_paused=values[9],
            robot_mode=mode,
            control_mode=values[11],
            target_speed_fraction=values[12],
            speed_scaling=values[13],
            target_speed_fraction_limit=values[14] if len(values) > 14 else None,
            reserved=values[15] if len(values) > 15 else None,
        )


_JOINT = struct.Struct(">dddffffB")  # q, q target, qd, current, voltage, motor T, micro T, mode
_JOINT_DATA_SIZE = _SUB_HEADER.size + JOINTS * _JOINT.size  # 251


@dataclass(frozen=True)
class JointState:
    """One joint in the joint data sub-package (rad, rad/s, A, V, °C)."""

    q_actual: float = 0.0
    q_target: float = 0.0
    qd_actual: float = 0.0
    current: float = 0.0
    voltage: float = 0.0
    motor_temperature: float = 0.0
    micro_temperature: float = 0.0
    joint_mode: int = 253  # JOINT_RUNNING_MODE (assumed: docs/ur.md)


@dataclass(frozen=True)
class JointData:
    """Sub-package 1: the six joints."""

    joints: tuple[JointState, ...]

    def __post_init__(self) -> None:
        if len(self.joints) != JOINTS:
            raise UrProtocolError(f"joint data has {len(self.joints)} joints, expected {JOINTS}")

    def encode(self) -> bytes:
        """The sub-package with its header."""
        body = b"".join(
            _JOINT.pack(
                j.q_actual,
                j.q_target,
                j.qd_actual,
                j.current,
                j.voltage,
                j.motor_temperature,
                j.micro_temperature,
                j.joint_mode,
            )
            for j in self.joints
        )
        return _SUB_HEADER.pack(_JOINT_DATA_SIZE, RobotStateType.JOINT_DATA) + body

    @classmethod
    def decode(cls, data: bytes) -> JointData:
        """Parse the sub-package (header included)."""
        if len(data) != _JOINT_DATA_SIZE:
            raise UrProtocolError(f"joint data of {len(data)} bytes, expected {_JOINT_DATA_SIZE}")
        joints = tuple(
            JointState(*_JOINT.unpack_from(data, _SUB_HEADER.size + i * _JOINT.size))
            for i in range(JOINTS)
        )
        return cls(joints)


# Masterboard data: the fixed part up to the safety mode, the reduced-mode flag and the
# euromap67/IMMI flag; then (if the flag is set) the IMMI block; the rest is kept as bytes.
_MASTERBOARD = struct.Struct(">IBIIBBddBBddffffBBB")
_IMMI = struct.Struct(">IIff")


@dataclass(frozen=True)
class MasterboardData:
    """Sub-package 3 as far as the OCU reads it: the I/O bits, voltages and the safety mode."""

    digital_input_bits: int = 0
    digital_output_bits: int = 0
    analog_input_range: tuple[int, int] = (0, 0)
    analog_input: tuple[float, float] = (0.0, 0.0)
    analog_output_domain: tuple[int, int] = (0, 0)
    analog_output: tuple[float, float] = (0.0, 0.0)
    temperature_c: float = 35.0
    robot_voltage_48v: float = 48.0
    robot_current_a: float = 0.0
    io_current_a: float = 0.0
    safety_mode: int = SafetyMode.NORMAL
    in_reduced_mode: bool = False
    immi: tuple[int, int, float, float] | None = None
    #: The bytes after the parsed fields (version dependent), as they came.
    tail: bytes = b""

    @property
    def safety(self) -> SafetyMode:
        """The safety mode as an enum."""
        return SafetyMode(self.safety_mode)

    def encode(self) -> bytes:
        """The sub-package with its header."""
        body_size = _MASTERBOARD.size + (_IMMI.size if self.immi else 0) + len(self.tail)
        head = _MASTERBOARD.pack(
            body_size,
            RobotStateType.MASTERBOARD_DATA,
            self.digital_input_bits,
            self.digital_output_bits,
            *self.analog_input_range,
            *self.analog_input,
            *self.analog_output_domain,
            *self.analog_output,
            self.temperature_c,
            self.robot_voltage_48v,
            self.robot_current_a,
            self.io_current_a,
            self.safety_mode,
            self.in_reduced_mode,
            1 if self.immi else 0,
        )
        return head + (_IMMI.pack(*self.immi) if self.immi else b"") + self.tail

    @classmethod
    def decode(cls, data: bytes) -> MasterboardData:
        """Parse the sub-package (header included)."""
        if len(data) < _MASTERBOARD.size:
            raise UrProtocolError(
                f"masterboard data of {len(data)} bytes, at least {_MASTERBOARD.size} expected"
            )
        v = _MASTERBOARD.unpack_from(data)
        safety = v[16]
        if safety not in SafetyMode._value2member_map_:
            raise UrProtocolError(f"safety mode {safety} is not a known safety mode")
        offset = _MASTERBOARD.size
        immi: tuple[int, int, float, float] | None = None
        if v[18]:
            if len(data) < offset + _IMMI.size:
                raise UrProtocolError("masterboard data: the IMMI block is cut short")
            immi = _IMMI.unpack_from(data, offset)
            offset += _IMMI.size
        return cls(
            digital_input_bits=v[2],
            digital_output_bits=v[3],
            analog_input_range=(v[4], v[5]),
            analog_input=(v[6], v[7]),
            analog_output_domain=(v[8], v[9]),
            analog_output=(v[10], v[11]),
            temperature_c=v[12],
            robot_voltage_48v=v[13],
            robot_current_a=v[14],
            io_current_a=v[15],
            safety_mode=safety,
            in_reduced_mode=bool(v[17]),
            immi=immi,
            tail=bytes(data[offset:]),
        )


@dataclass(frozen=True)
class UnknownSubPackage:
    """A robot-state sub-package the OCU does not read, kept whole."""

    kind: int
    data: bytes

    def encode(self) -> bytes:
        """The sub-package as it came."""
        return self.data


SubPackage = RobotModeData | JointData | MasterboardData | UnknownSubPackage
_SUB_DECODERS: dict[int, Callable[[bytes], SubPackage]] = {
    RobotStateType.ROBOT_MODE_DATA: RobotModeData.decode,
    RobotStateType.JOINT_DATA: JointData.decode,
    RobotStateType.MASTERBOARD_DATA: MasterboardData.decode,
}


@dataclass(frozen=True)
class RobotState:
    """A ROBOT_STATE packet (type 16): its sub-packages in order."""

    packages: tuple[SubPackage, ...]

    def find(self, kind: type[SubPackage]) -> SubPackage | None:
        """The first sub-package of a class, or None."""
        return next((p for p in self.packages if isinstance(p, kind)), None)

    @property
    def robot_mode(self) -> RobotModeData | None:
        """The robot mode data, if the packet has it."""
        found = self.find(RobotModeData)
        return found if isinstance(found, RobotModeData) else None

    @property
    def joint_data(self) -> JointData | None:
        """The joint data, if the packet has it."""
        found = self.find(JointData)
        return found if isinstance(found, JointData) else None

    @property
    def masterboard(self) -> MasterboardData | None:
        """The masterboard data (with the safety mode), if the packet has it."""
        found = self.find(MasterboardData)
        return found if isinstance(found, MasterboardData) else None

    def encode(self) -> bytes:
        """The whole packet."""
        body = b"".join(p.encode() for p in self.packages)
        return _HEADER.pack(_HEADER.size + len(body), PackageType.ROBOT_STATE) + body

    @classmethod
    def decode(cls, data: bytes) -> RobotState:
        """Parse a whole ROBOT_STATE packet; a sub-package's bad length is an error."""
        _check_frame(data, PackageType.ROBOT_STATE)
        offset = _HEADER.size
        packages: list[SubPackage] = []
        while offset < len(data):
            if offset + _SUB_HEADER.size > len(data):
                raise UrProtocolError(
                    f"robot state: {len(data) - offset} bytes left, too few for a sub-package"
                )
            size, kind = _SUB_HEADER.unpack_from(data, offset)
            if size < _SUB_HEADER.size or offset + size > len(data):
                raise UrProtocolError(
                    f"robot state: sub-package type {kind} says {size} bytes at offset {offset}, "
                    f"{len(data) - offset} left"
                )
            chunk = bytes(data[offset : offset + size])
            decoder = _SUB_DECODERS.get(kind)
            package: SubPackage = decoder(chunk) if decoder else UnknownSubPackage(kind, chunk)
            packages.append(package)
            offset += size
        return cls(tuple(packages))


@dataclass(frozen=True)
class UnknownPackage:
    """A primary packet the OCU does not read (GUI messages and others), kept whole."""

    kind: int
    data: bytes


PrimaryPackage = VersionMessage | RobotState | UnknownPackage


def decode_primary(data: bytes) -> PrimaryPackage:
    """Parse one whole primary/secondary packet."""
    if len(data) < _HEADER.size:
        raise UrProtocolError(f"packet of {len(data)} bytes is shorter than its header (5)")
    length, kind = _HEADER.unpack_from(data)
    if length != len(data):
        raise UrProtocolError(f"length field says {length} bytes, got {len(data)}")
    if kind == PackageType.ROBOT_STATE:
        return RobotState.decode(data)
    if (
        kind == PackageType.ROBOT_MESSAGE
        and len(data) >= _MESSAGE_HEADER.size
        and _MESSAGE_HEADER.unpack_from(data)[4] == ROBOT_MESSAGE_VERSION
    ):
        return VersionMessage.decode(data)
    return UnknownPackage(kind, bytes(data))


# ---- the stream splitter ---------------------------------------------------------------------


class StreamSplitter:
    """Whole packets out of a TCP byte stream that arrives in arbitrary pieces.

    A packet is accepted when its length field is plausible: one of `sizes` (the realtime
    port) or within [5, MAX_PRIMARY_SIZE] with a known packet type (primary/secondary). On an
    implausible header one byte is skipped and the search goes on, so a stream regains sync at
    the next good header; `malformed` counts each such episode, `skipped_bytes` the bytes lost.
    """

    def __init__(self, *, sizes: Iterable[int] | None = None) -> None:
        self._sizes = frozenset(sizes) if sizes is not None else None
        self._buffer = bytearray()
        self._in_garbage = False
        self.malformed = 0
        self.skipped_bytes = 0
        self.packets = 0

    @classmethod
    def realtime(cls, sizes: Iterable[int] = KNOWN_REALTIME_SIZES) -> StreamSplitter:
        """A splitter for the realtime port (sizes: the layouts accepted)."""
        return cls(sizes=sizes)

    @classmethod
    def primary(cls) -> StreamSplitter:
        """A splitter for the primary and secondary ports."""
        return cls()

    @property
    def pending(self) -> int:
        """Bytes held waiting for the rest of a packet."""
        return len(self._buffer)

    def _plausible(self, offset: int) -> bool:
        length = _LENGTH.unpack_from(self._buffer, offset)[0]
        if self._sizes is not None:
            return length in self._sizes
        if not _HEADER.size <= length <= MAX_PRIMARY_SIZE:
            return False
        return self._buffer[offset + 4] in PackageType._value2member_map_

    def feed(self, data: bytes) -> list[bytes]:
        """Add received bytes; the whole packets now complete, in order."""
        self._buffer += data
        packets: list[bytes] = []
        header = _LENGTH.size if self._sizes is not None else _HEADER.size
        offset = 0
        while len(self._buffer) - offset >= header:
            if not self._plausible(offset):
                if not self._in_garbage:
                    self._in_garbage = True
                    self.malformed += 1
                offset += 1
                self.skipped_bytes += 1
                continue
            length = _LENGTH.unpack_from(self._buffer, offset)[0]
            if len(self._buffer) - offset < length:
                break
            self._in_garbage = False
            packets.append(bytes(self._buffer[offset : offset + length]))
            offset += length
        del self._buffer[:offset]
        self.packets += len(packets)
        return packets


# ---- URScript motion commands ----------------------------------------------------------------


def _vector(values: Sequence[float], what: str) -> str:
    if len(values) != JOINTS:
        raise UrProtocolError(f"{what} has {len(values)} values, expected {JOINTS}")
    for value in values:
        if not math.isfinite(value):
            raise UrProtocolError(f"{what} holds a non-finite value {value!r}")
    return "[" + ",".join(f"{v:.6f}" for v in values) + "]"


def _number(value: float, what: str, *, positive: bool = False) -> str:
    if not math.isfinite(value) or (positive and value <= 0) or value < 0:
        need = "> 0" if positive else ">= 0"
        raise UrProtocolError(f"{what} must be finite and {need}, got {value!r}")
    return f"{value:.6f}"


def speedj(qd: Sequence[float], a: float, t: float) -> bytes:
    """`speedj(qd, a, t)`: joint speeds (rad/s), acceleration (rad/s²), time to run (s)."""
    return (
        f"speedj({_vector(qd, 'qd')},{_number(a, 'a', positive=True)},{_number(t, 't')})\n"
    ).encode()


def stopj(a: float) -> bytes:
    """`stopj(a)`: decelerate every joint to rest at a (rad/s²)."""
    return f"stopj({_number(a, 'a', positive=True)})\n".encode()


def servoj(q: Sequence[float], t: float, lookahead_time: float = 0.1, gain: float = 300.0) -> bytes:
    """`servoj(q, 0, 0, t, lookahead_time, gain)`: follow a joint position for t seconds."""
    return (
        f"servoj({_vector(q, 'q')},0,0,{_number(t, 't', positive=True)},"
        f"{_number(lookahead_time, 'lookahead_time', positive=True)},"
        f"{_number(gain, 'gain', positive=True)})\n"
    ).encode()


def movej(q: Sequence[float], a: float, v: float) -> bytes:
    """`movej(q, a, v)`: move to joint position q with acceleration a and speed v."""
    return (
        f"movej({_vector(q, 'q')},a={_number(a, 'a', positive=True)},"
        f"v={_number(v, 'v', positive=True)})\n"
    ).encode()


@dataclass(frozen=True)
class ScriptCommand:
    """One URScript motion call as the controller understood it (defaults filled in)."""

    name: str
    q: Vector6 | None = None
    qd: Vector6 | None = None
    a: float = 0.0
    v: float = 0.0
    t: float = 0.0
    lookahead_time: float = 0.1
    gain: float = 300.0


_CALL = re.compile(r"^\s*(?P<name>[a-z_]+)\s*\((?P<args>.*)\)\s*$", re.DOTALL)
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_TOKEN = re.compile(rf"\s*(?:(?P<key>[a-z_]+)\s*=\s*)?(?P<value>\[[^\]]*\]|{_NUMBER})\s*(?:,|$)")
#: Each call's parameters in order, with their defaults (URScript manual; docs/ur.md).
_SIGNATURES: dict[str, tuple[tuple[str, float | None], ...]] = {
    "speedj": (("qd", None), ("a", None), ("t", 0.0)),
    "stopj": (("a", None),),
    "servoj": (
        ("q", None),
        ("a", 0.0),
        ("v", 0.0),
        ("t", 0.002),
        ("lookahead_time", 0.1),
        ("gain", 300.0),
    ),
    "movej": (("q", None), ("a", 1.4), ("v", 1.05), ("t", 0.0), ("r", 0.0)),
}
_VECTORS = {"q", "qd"}


def parse_script_line(line: str) -> ScriptCommand:
    """Parse one URScript line of the subset the simulator runs (speedj, stopj, servoj, movej).

    UrProtocolError for anything else: another function, a pose (p[...]) where joints are
    expected, a wrong count, a non-finite number, a negative time or acceleration.
    """
    match = _CALL.match(line)
    if match is None:
        raise UrProtocolError(f"not a URScript call: {line[:60]!r}")
    name = match["name"]
    signature = _SIGNATURES.get(name)
    if signature is None:
        raise UrProtocolError(f"{name}() is not in the simulator's URScript subset")
    args = match["args"]
    values: dict[str, float | Vector6] = {}
    position = 0
    offset = 0
    params = [p for p, _ in signature]
    while offset < len(args):
        token = _TOKEN.match(args, offset)
        if token is None or token.end() == offset:
            raise UrProtocolError(f"{name}(): cannot read the arguments at {args[offset:][:30]!r}")
        offset = token.end()
        key = token["key"]
        if key is None:
            if values.keys() - set(params[:position]):
                raise UrProtocolError(f"{name}(): a positional argument after a keyword one")
            if position >= len(params):
                raise UrProtocolError(f"{name}() takes at most {len(params)} arguments")
            key = params[position]
            position += 1
        elif key not in params:
            raise UrProtocolError(f"{name}() has no parameter {key!r}")
        elif key in values:
            raise UrProtocolError(f"{name}(): {key} given twice")
        values[key] = _parse_value(name, key, token["value"])
    for param, default in signature:
        if param not in values:
            if default is None:
                raise UrProtocolError(f"{name}(): {param} is required")
            values[param] = default
    scalars = {k: v for k, v in values.items() if isinstance(v, float)}
    for key in ("a", "v", "t", "lookahead_time", "gain"):
        if scalars.get(key, 0.0) < 0:
            raise UrProtocolError(f"{name}(): {key} must be >= 0, got {scalars[key]}")
    if name == "stopj" and scalars["a"] <= 0:
        raise UrProtocolError("stopj(): a must be > 0")
    vector = {k: v for k, v in values.items() if isinstance(v, tuple)}
    return ScriptCommand(
        name=name,
        q=vector.get("q"),
        qd=vector.get("qd"),
        a=scalars.get("a", 0.0),
        v=scalars.get("v", 0.0),
        t=scalars.get("t", 0.0),
        lookahead_time=scalars.get("lookahead_time", 0.1),
        gain=scalars.get("gain", 300.0),
    )


def _parse_value(name: str, key: str, text: str) -> float | Vector6:
    if text.startswith("["):
        if key not in _VECTORS:
            raise UrProtocolError(f"{name}(): {key} is a number, not a list")
        items = [item.strip() for item in text[1:-1].split(",")]
        if len(items) != JOINTS or not all(re.fullmatch(_NUMBER, item) for item in items):
            raise UrProtocolError(f"{name}(): {key} must be a list of {JOINTS} numbers: {text}")
        vector = tuple(float(item) for item in items)
        return (vector[0], vector[1], vector[2], vector[3], vector[4], vector[5])
    if key in _VECTORS:
        raise UrProtocolError(f"{name}(): {key} must be a list of {JOINTS} joint values")
    value = float(text)
    if not math.isfinite(value):
        raise UrProtocolError(f"{name}(): {key} is not finite")
    return value
