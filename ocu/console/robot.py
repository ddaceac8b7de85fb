"""What the console knows about the robot: the one copy every view reads (no Qt).

The window feeds it link events (at most ~30 telemetry frames a second); views subscribe to
its events and read it: the latest reading of every motor with its age and plausibility, the
history the plots draw, the link's state and statistics, the extension's status (battery,
headlight, roll/pitch). No view keeps a copy of its own.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable

from ocu.console.events import Event
from ocu.profile import RobotProfile
from ocu.records import (
    JointReading,
    LinkState,
    LinkStats,
    RobotModeReport,
    StatusFrame,
    TelemetryFrame,
)

DEFAULT_HISTORY_S = 60.0

# One plotted sample: arrival time, angle (degrees, None when unknown or not believed),
# speed and current.
Sample = tuple[float, float | None, float, float]


class RobotEvents:
    """What a view may subscribe to."""

    def __init__(self) -> None:
        self.telemetry_changed: Event[[TelemetryFrame]] = Event()
        self.link_state_changed: Event[[LinkState, str]] = Event()
        self.stats_changed: Event[[LinkStats]] = Event()
        self.status_changed: Event[[StatusFrame]] = Event()
        self.extension_changed: Event[[bool, str]] = Event()
        self.robot_mode_changed: Event[[RobotModeReport | None]] = Event()


class RobotState:
    """The latest telemetry, link state, statistics and status, with a plot history."""

    # A part of the console model: the GUI reaches it under the model's lock (ocu.core.guard).
    guarded = True

    def __init__(
        self,
        profile: RobotProfile,
        *,
        history_s: float = DEFAULT_HISTORY_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.profile = profile
        self.clock = clock
        self.history_s = history_s
        self.events = RobotEvents()
        self.frame: TelemetryFrame | None = None
        self.readings: dict[str, JointReading] = {}
        self._fresh_at: dict[str, float] = {}
        self.history: dict[str, deque[Sample]] = {name: deque() for name in profile.motors}
        self.link_state = LinkState.CONNECTING
        # The controller's own mode (None: it reports none, or not yet).
        self.robot_mode: RobotModeReport | None = None
        self.link_reason = ""
        self.stats: LinkStats | None = None
        self.status: StatusFrame | None = None
        self.extension_active = False

    # ---- input (the window, from link events) ----------------------------------------------

    def on_telemetry(self, frame: TelemetryFrame) -> None:
        """A telemetry frame: the readings it holds replace the older ones."""
        self.frame = frame
        at = frame.received_at
        for name, reading in frame.readings.items():
            self.readings[name] = reading
            self._fresh_at[name] = at
            series = self.history.get(name)
            if series is None:
                continue
            # An implausible angle (-11796480° for a broken encoder) would flatten a plot.
            angle = None
            if reading.angle_rad is not None and reading.fault is None:
                angle = math.degrees(reading.angle_rad)
            series.append((at, angle, reading.speed_rad_s, reading.current_a))
            while series and series[0][0] < at - self.history_s:
                series.popleft()
        self.events.telemetry_changed.emit(frame)

    def on_link_state(self, state: LinkState, reason: str) -> None:
        """The link's state changed; CONNECTING forgets the last telemetry's time."""
        self.link_state = state
        self.link_reason = reason
        if state is LinkState.CONNECTING:
            self.frame = None
        self.events.link_state_changed.emit(state, reason)
        if state is not LinkState.CONNECTED and self.robot_mode is not None:
            self.on_robot_mode(None)  # not heard: the mode is not known any more

    def on_stats(self, stats: LinkStats) -> None:
        """New counters and rates."""
        self.stats = stats
        self.events.stats_changed.emit(stats)

    def on_status(self, status: StatusFrame) -> None:
        """An extension status packet."""
        self.status = status
        self.events.status_changed.emit(status)

    def on_extension(self, active: bool, reason: str) -> None:
        """The robot started or stopped speaking the protocol extension."""
        self.extension_active = active
        if not active:
            self.status = None
        self.events.extension_changed.emit(active, reason)

    def on_robot_mode(self, report: RobotModeReport | None) -> None:
        """The controller's own mode changed (a UR's robot and safety modes; None: unknown)."""
        self.robot_mode = report
        self.events.robot_mode_changed.emit(report)

    # ---- what views read -------------------------------------------------------------------

    @property
    def last_telemetry_at(self) -> float | None:
        """When the latest telemetry arrived (monotonic), None before any."""
        return None if self.frame is None else self.frame.received_at

    def telemetry_age(self, now: float | None = None) -> float | None:
        """Seconds since the latest telemetry, None before any."""
        last = self.last_telemetry_at
        return None if last is None else (self.clock() if now is None else now) - last

    def fresh_at(self, joint: str) -> float | None:
        """When a reading of this joint last arrived."""
        return self._fresh_at.get(joint)

    def faults(self) -> dict[str, str]:
        """Joint name to why its latest reading is implausible."""
        return {name: r.fault for name, r in self.readings.items() if r.fault is not None}

    def angles(self) -> dict[str, float]:
        """The latest believable angle of every joint that reports one."""
        return {
            name: r.angle_rad
            for name, r in self.readings.items()
            if r.angle_rad is not None and r.fault is None and math.isfinite(r.angle_rad)
        }
