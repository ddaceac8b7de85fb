"""The primary and secondary interfaces (ports 30001, 30002): framed packages, the version
message, the robot state and its sub-packages, and the TCP stream splitter (docs/ur.md)."""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from enum import IntEnum

from ocu.protocol.ur.common import JOINTS, RobotMode, SafetyMode, UrProtocolError
from ocu.protocol.ur.realtime import KNOWN_REALTIME_SIZES, LENGTH_FIELD

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


#: Skipped bytes kept for take_skipped() at most (a reader that never takes them).
MAX_KEPT_SKIPPED = 65536


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
        self._skipped = bytearray()
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
        length = LENGTH_FIELD.unpack_from(self._buffer, offset)[0]
        if self._sizes is not None:
            return length in self._sizes
        if not _HEADER.size <= length <= MAX_PRIMARY_SIZE:
            return False
        return self._buffer[offset + 4] in PackageType._value2member_map_

    def feed(self, data: bytes) -> list[bytes]:
        """Add received bytes; the whole packets now complete, in order."""
        self._buffer += data
        packets: list[bytes] = []
        header = LENGTH_FIELD.size if self._sizes is not None else _HEADER.size
        offset = 0
        while len(self._buffer) - offset >= header:
            if not self._plausible(offset):
                if not self._in_garbage:
                    self._in_garbage = True
                    self.malformed += 1
                if len(self._skipped) < MAX_KEPT_SKIPPED:
                    self._skipped.append(self._buffer[offset])
                offset += 1
                self.skipped_bytes += 1
                continue
            length = LENGTH_FIELD.unpack_from(self._buffer, offset)[0]
            if len(self._buffer) - offset < length:
                break
            self._in_garbage = False
            packets.append(bytes(self._buffer[offset : offset + length]))
            offset += length
        del self._buffer[:offset]
        self.packets += len(packets)
        return packets

    def take_skipped(self) -> bytes:
        """The bytes skipped since the last call, in order (a recording keeps them)."""
        skipped = bytes(self._skipped)
        self._skipped.clear()
        return skipped
