"""The ROS bridge's state and diagnostics, without ROS or Qt.

Who may move the robot through the bridge (`BridgeState`), whether the link lets ROS drive
(`LinkGate`), a snapshot of the bridge (`BridgeStatus`), and the diagnostic_msgs reports of
the bridge and of the link that `/diagnostics` publishes (`bridge_report`, `link_report`), and
of a UR controller's robot and safety modes (`controller_report`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum, IntEnum

from ocu.link.history import UPLINK_LOSS_UNMEASURABLE
from ocu.link.ur_wire import UrRobotStatus
from ocu.protocol.ur import SafetyMode
from ocu.records import LinkState, LinkStats
from ocu.ros.convert import DEFAULT_CMD_VEL_TIMEOUT_S

__all__ = [
    "LOSS_WARNING",
    "STATE_TEXT",
    "BridgeState",
    "BridgeStatus",
    "DiagnosticLevel",
    "DiagnosticReport",
    "LinkGate",
    "bridge_report",
    "controller_report",
    "gate_text",
    "link_report",
]

# Telemetry loss above this fraction makes the link diagnostics a warning.
LOSS_WARNING = 0.2


class BridgeState(Enum):
    """Who may move the robot through the bridge."""

    OFF = "off"
    LISTENING = "listening"
    COMMANDING = "commanding"
    OVERRIDDEN = "overridden"


STATE_TEXT = {
    BridgeState.OFF: "ROS control off",
    BridgeState.LISTENING: "ROS control on: waiting for commands",
    BridgeState.COMMANDING: "ROS is commanding the robot",
    BridgeState.OVERRIDDEN: "ROS control overridden by the operator",
}


class LinkGate(Enum):
    """Whether the link lets ROS move the robot (the Link's state, seen by the bridge)."""

    OPEN = "open"
    # LOST or CLOSED: zeros whatever cmd_vel says; joint goals cancelled and refused.
    LOST = "link lost"
    # CONNECTED again: a non-zero cmd_vel is refused until cmd_vel has been zero or silent
    # for the cmd_vel timeout, so recovery never resumes motion by itself.
    RECOVERING = "recovering"


def gate_text(gate: LinkGate, timeout_s: float) -> str:
    """What the gate means for cmd_vel, for logs and diagnostics."""
    if gate is LinkGate.LOST:
        return "LINK LOST: cmd_vel refused, zeros sent"
    if gate is LinkGate.RECOVERING:
        return f"link back: cmd_vel refused until it has been zero or silent for {timeout_s:.2f} s"
    return "link up: cmd_vel obeyed"


@dataclass(frozen=True)
class BridgeStatus:
    """A snapshot of the bridge for diagnostics and the console."""

    state: BridgeState
    drive: dict[str, float]
    goals_rad: dict[str, float]
    cmd_vel_age_s: float | None
    cmd_vel_count: int
    rejected_count: int
    timeouts: int
    link_gate: LinkGate = LinkGate.OPEN
    link_refused_count: int = 0
    cmd_vel_timeout_s: float = DEFAULT_CMD_VEL_TIMEOUT_S


class DiagnosticLevel(IntEnum):
    """diagnostic_msgs/DiagnosticStatus levels."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


@dataclass(frozen=True)
class DiagnosticReport:
    """One diagnostic_msgs/DiagnosticStatus, ROS-free."""

    name: str
    level: DiagnosticLevel
    message: str
    hardware_id: str
    values: tuple[tuple[str, str], ...]


def _optional(value: float | None, fmt: str) -> str:
    return "n/a" if value is None else format(value, fmt)


def _ms(value_s: float | None) -> float | None:
    return None if value_s is None else value_s * 1e3


def link_report(state: LinkState, stats: LinkStats, hardware_id: str) -> DiagnosticReport:
    """Link health: state, rates, loss, malformed/foreign counts, e-stop latch."""
    if state is LinkState.CONNECTED:
        level, message = DiagnosticLevel.OK, "connected"
        if stats.estop_latched:
            level, message = DiagnosticLevel.WARN, "connected, emergency stop latched"
        elif stats.loss_estimate is not None and stats.loss_estimate > LOSS_WARNING:
            level = DiagnosticLevel.WARN
            message = f"connected, telemetry loss {stats.loss_estimate:.0%}"
    elif state is LinkState.CONNECTING:
        level, message = DiagnosticLevel.WARN, "connecting: no packet from the robot yet"
    elif state is LinkState.LOST:
        level, message = DiagnosticLevel.ERROR, "LINK LOST: no valid packet from the robot"
    else:
        level, message = DiagnosticLevel.ERROR, "link closed"
    values = (
        ("state", state.label),
        ("datagrams sent", str(stats.sent)),
        ("valid packets received", str(stats.received)),
        ("telemetry packets", str(stats.telemetry)),
        ("video frames", str(stats.video)),
        ("malformed datagrams", str(stats.malformed)),
        ("foreign datagrams", str(stats.foreign)),
        ("send errors", str(stats.send_errors)),
        ("command rate (Hz)", f"{stats.rcp_rate_hz:.1f}"),
        ("telemetry rate (Hz)", f"{stats.telemetry_rate_hz:.1f}"),
        ("video rate (Hz)", f"{stats.video_rate_hz:.1f}"),
        ("telemetry loss", _optional(stats.loss_estimate, ".3f")),
        ("duplicates", str(stats.duplicates)),
        ("reordered", str(stats.reordered)),
        ("last valid packet age (s)", _optional(stats.last_valid_age_s, ".2f")),
        ("send rate setting (Hz)", f"{stats.send_rate_hz:g}"),
        ("emergency stop latched", str(stats.estop_latched).lower()),
        ("round trip (ms)", _optional(_ms(stats.delay_s), ".0f")),
        ("delay jitter (ms)", _optional(_ms(stats.jitter_s), ".0f")),
        ("scan rate (Hz)", f"{stats.scan_rate_hz:.1f}"),
        (
            "command loss",
            UPLINK_LOSS_UNMEASURABLE
            if stats.uplink_loss is None
            else format(stats.uplink_loss, ".3f"),
        ),
        *(
            (f"frame age camera {index} (s)", _optional(age, ".2f"))
            for index, age in enumerate(stats.frame_age_s)
        ),
    )
    return DiagnosticReport("ocu: robot link", level, message, hardware_id, values)


def bridge_report(status: BridgeStatus, hardware_id: str) -> DiagnosticReport:
    """Bridge health: who commands, the link gate, cmd_vel age, goals, rejections, timeouts."""
    level = DiagnosticLevel.OK
    message = STATE_TEXT[status.state]
    if status.state in (BridgeState.OFF, BridgeState.OVERRIDDEN):
        level = DiagnosticLevel.WARN
    if status.link_gate is not LinkGate.OPEN:
        level = DiagnosticLevel.ERROR if status.link_gate is LinkGate.LOST else DiagnosticLevel.WARN
        message = f"{message}; {gate_text(status.link_gate, status.cmd_vel_timeout_s)}"
    goals = ", ".join(f"{j}={math.degrees(a):.1f}°" for j, a in status.goals_rad.items())
    values = (
        ("state", status.state.value),
        ("link gate", status.link_gate.value),
        *(
            (f"{name} ({unit})", f"{status.drive.get(name, 0.0):.3f}")
            for name, unit in zip(status.drive, ("m/s", "rad/s"), strict=False)
        ),
        *((("cmd_vel", "refused: no chassis (no drive channels)"),) if not status.drive else ()),
        ("last cmd_vel age (s)", _optional(status.cmd_vel_age_s, ".2f")),
        ("cmd_vel timeout (s)", f"{status.cmd_vel_timeout_s:g}"),
        ("cmd_vel received", str(status.cmd_vel_count)),
        ("cmd_vel timeouts", str(status.timeouts)),
        ("cmd_vel refused (link)", str(status.link_refused_count)),
        ("joint goals", goals or "none"),
        ("rejected commands", str(status.rejected_count)),
    )
    return DiagnosticReport("ocu: ROS bridge", level, message, hardware_id, values)


def controller_report(status: UrRobotStatus | None, hardware_id: str) -> DiagnosticReport:
    """A UR controller's robot mode, safety mode and stop flags (its secondary port's report):
    OK while it takes motion, WARN in reduced mode, ERROR otherwise, STALE before the first."""
    if status is None:
        return DiagnosticReport(
            "ocu: robot controller",
            DiagnosticLevel.STALE,
            "no robot state from the controller yet",
            hardware_id,
            (("robot mode", "unknown"), ("safety mode", "unknown")),
        )
    if not status.may_move:
        level = DiagnosticLevel.ERROR
    elif status.safety_mode is SafetyMode.REDUCED:
        level = DiagnosticLevel.WARN
    else:
        level = DiagnosticLevel.OK
    values = (
        ("robot mode", status.robot_mode.name),
        ("safety mode", status.safety_mode.name),
        ("emergency stopped", str(status.emergency_stopped).lower()),
        ("protective stopped", str(status.protective_stopped).lower()),
        ("takes motion", str(status.may_move).lower()),
    )
    return DiagnosticReport("ocu: robot controller", level, status.describe(), hardware_id, values)
