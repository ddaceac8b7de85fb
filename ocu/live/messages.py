"""The messages a live client may publish (`--live-control`) and the services it may call,
decoded strictly from JSON or CDR (docs/live.md).

| topic | types taken | what |
| --- | --- | --- |
| `/cmd_vel` | `geometry_msgs/msg/Twist` (or the ROS 1 name) | the drive pair: linear.x, angular.z |
| `/joint_goals` | `sensor_msgs/msg/JointState` | name[] with position[] in radians |
| `/arm/twist_cmd` | `geometry_msgs/msg/TwistStamped` | tool0's velocity, the arm's base frame |
| `/arm/named_pose` | `std_msgs/msg/String` | a stored pose by name |

A message that is not one of these (not JSON, a missing field, a number that is not finite,
bytes that are not the CDR of the type) raises `InputError` with the reason.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final

from mcap_ros2._dynamic import DecoderFunction, generate_dynamic

from ocu.record import schemas as s

CMD_VEL: Final = "/cmd_vel"
JOINT_GOALS: Final = "/joint_goals"
ARM_TWIST: Final = "/arm/twist_cmd"
NAMED_POSE: Final = "/arm/named_pose"
ENCODINGS: Final = ("json", "cdr")
# The longest list a joint goal may give (an arm has a handful of joints).
MAX_JOINTS: Final = 64
MAX_NAME_CHARS: Final = 256

TWIST_STAMPED = s.MessageType(
    "geometry_msgs/msg/TwistStamped",
    s.concatenate(
        "std_msgs/Header header\nTwist twist\n",
        ("std_msgs/Header", "builtin_interfaces/Time stamp\nstring frame_id\n"),
        ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"),
        ("geometry_msgs/Twist", "Vector3 linear\nVector3 angular\n"),
        ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
    ),
)
STRING = s.MessageType("std_msgs/msg/String", "string data\n")


class InputError(ValueError):
    """A client's message that is not what its topic takes."""


@dataclass(frozen=True)
class JointGoal:
    """/joint_goals: target angles (rad) by joint name; both empty cancels every goal."""

    names: tuple[str, ...]
    positions_rad: tuple[float, ...]


@dataclass(frozen=True)
class ArmTwist:
    """/arm/twist_cmd: tool0's linear (m/s) and angular (rad/s) velocity in `frame_id`."""

    frame_id: str
    linear: tuple[float, float, float]
    angular: tuple[float, float, float]


def _names(ros2: str) -> tuple[str, str]:
    """A ROS 2 type name and the ROS 1 name Lichtblick's panels give."""
    return ros2, ros2.replace("/msg/", "/")


def _finite(value: object, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"{what} must be a finite number, not {value!r:.40}")
    return float(value)


def _text(value: object, what: str) -> str:
    if not isinstance(value, str) or len(value) > MAX_NAME_CHARS:
        raise InputError(f"{what} must be a string of at most {MAX_NAME_CHARS} characters")
    return value


def _vector(value: Any, what: str) -> tuple[float, float, float]:
    def part(axis: str) -> float:
        item = value[axis] if isinstance(value, dict) else getattr(value, axis)
        return _finite(item, f"{what}.{axis}")

    return part("x"), part("y"), part("z")


def _twist(message: Any) -> tuple[float, float]:
    linear, angular = _field(message, "linear"), _field(message, "angular")
    return _vector(linear, "linear")[0], _vector(angular, "angular")[2]


def _field(message: Any, name: str) -> Any:
    return message[name] if isinstance(message, dict) else getattr(message, name)


def _joint_goal(message: Any) -> JointGoal:
    names, positions = _field(message, "name"), _field(message, "position")
    if not isinstance(names, list | tuple) or not isinstance(positions, list | tuple):
        raise InputError("name and position must be lists")
    if len(names) > MAX_JOINTS or len(positions) > MAX_JOINTS:
        raise InputError(f"a joint goal names at most {MAX_JOINTS} joints")
    checked = tuple(_text(name, "a joint name") for name in names)
    return JointGoal(checked, tuple(_finite(p, "a position") for p in positions))


def _arm_twist(message: Any) -> ArmTwist:
    header, twist = _field(message, "header"), _field(message, "twist")
    frame = _text(_field(header, "frame_id"), "header.frame_id")
    linear = _vector(_field(twist, "linear"), "twist.linear")
    angular = _vector(_field(twist, "angular"), "twist.angular")
    return ArmTwist(frame, linear, angular)


def _named_pose(message: Any) -> str:
    return _text(_field(message, "data"), "data")


@dataclass(frozen=True)
class _Input:
    message_type: s.MessageType
    read: Callable[[Any], Any]

    @property
    def schemas(self) -> tuple[str, str]:
        return _names(self.message_type.name)


INPUTS: Final = {
    CMD_VEL: _Input(s.TWIST, _twist),
    JOINT_GOALS: _Input(s.JOINT_STATE, _joint_goal),
    ARM_TWIST: _Input(TWIST_STAMPED, _arm_twist),
    NAMED_POSE: _Input(STRING, _named_pose),
}
_DECODERS: dict[str, DecoderFunction] = {}


def schemas_of(topic: str) -> tuple[str, ...]:
    """The schema names a client may advertise for a topic (none: not a topic it may use)."""
    entry = INPUTS.get(topic)
    return entry.schemas if entry is not None else ()


def decode(topic: str, encoding: str, payload: bytes) -> Any:
    """One message on a client's topic: (linear.x, angular.z) for /cmd_vel, a JointGoal, an
    ArmTwist or a pose name; InputError if it is not one."""
    entry = INPUTS[topic]
    name = entry.message_type.name
    short = name.rsplit("/", 1)[-1]
    if encoding == "json":
        try:
            return entry.read(json.loads(payload))
        except InputError:
            raise
        except (ValueError, KeyError, TypeError, AttributeError, RecursionError) as err:
            raise InputError(f"not a JSON {short}: {err}") from err
    decoder = _DECODERS.get(name)
    if decoder is None:
        decoder = generate_dynamic(name, entry.message_type.definition)[name]
        _DECODERS[name] = decoder
    try:
        return entry.read(decoder(payload))
    except InputError:
        raise
    except Exception as err:  # the generated decoder raises what the bytes make it raise
        raise InputError(f"not a CDR {short}: {type(err).__name__}: {err}") from err
