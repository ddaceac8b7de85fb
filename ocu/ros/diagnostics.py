"""The ROS bridge's state and diagnostics, without ROS or Qt.

Who may move the robot through the bridge (`BridgeState`), whether the link lets ROS drive
(`LinkGate`), a snapshot of the bridge (`BridgeStatus`), and the diagnostic_msgs reports of
the bridge and of the link that `/diagnostics` publishes (`bridge_report`; `link_report`,
from ocu.link.diagnostics, which the live server publishes too), and of a UR controller's
robot and safety modes (`controller_report`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from ocu.link.diagnostics import (
    LOSS_WARNING,
    DiagnosticLevel,
    DiagnosticReport,
    link_report,
    optional_text,
)
from ocu.link.ur_wire import UrRobotStatus
from ocu.protocol.ur import SafetyMode
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
        ("last cmd_vel age (s)", optional_text(status.cmd_vel_age_s, ".2f")),
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
