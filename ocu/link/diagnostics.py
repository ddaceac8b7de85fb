"""The link's health as a diagnostic_msgs/DiagnosticStatus, without ROS: what `ocu-ros` and
the live server (`ocu --live`) publish on /diagnostics."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from ocu.link.history import UPLINK_LOSS_UNMEASURABLE
from ocu.records import LinkState, LinkStats

# Telemetry loss above this fraction makes the link diagnostics a warning.
LOSS_WARNING = 0.2


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


def optional_text(value: float | None, fmt: str) -> str:
    """A measured value as text; "n/a" when unknown."""
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
        ("telemetry loss", optional_text(stats.loss_estimate, ".3f")),
        ("duplicates", str(stats.duplicates)),
        ("reordered", str(stats.reordered)),
        ("last valid packet age (s)", optional_text(stats.last_valid_age_s, ".2f")),
        ("send rate setting (Hz)", f"{stats.send_rate_hz:g}"),
        ("emergency stop latched", str(stats.estop_latched).lower()),
        ("round trip (ms)", optional_text(_ms(stats.delay_s), ".0f")),
        ("delay jitter (ms)", optional_text(_ms(stats.jitter_s), ".0f")),
        ("scan rate (Hz)", f"{stats.scan_rate_hz:.1f}"),
        (
            "command loss",
            UPLINK_LOSS_UNMEASURABLE
            if stats.uplink_loss is None
            else format(stats.uplink_loss, ".3f"),
        ),
        *(
            (f"frame age camera {index} (s)", optional_text(age, ".2f"))
            for index, age in enumerate(stats.frame_age_s)
        ),
    )
    return DiagnosticReport("ocu: robot link", level, message, hardware_id, values)
