"""How the link behaved over the last minutes: a rolling history of its statistics, with
LINK LOST and e-stop events on the same time axis (no Qt).

A `LinkHistory` is a link listener (subscribe it to any Link: live, virtual or a replay). It
keeps every `LinkStats` the link emits (twice a second live; at the recorded pace in a
replay) for `span_s` seconds, stamped with its clock, and marks the moments the link was
lost and came back and the emergency stops. The Link dock (ocu.widgets.link_graphs) draws
it; `series` hands out the figures as arrays over a time range. While nothing has arrived
from the robot for `SILENT_AFTER_S`, the downlink loss reads 100 % and the round trip and
its jitter are unknown (the link's own figures keep their last values then: they are
measured on what arrives).

What the OCU cannot know is said, not invented: the loss of commands on their way to the
robot (uplink) needs the robot to tell which commands it received. An extended robot echoes
its sequenced RCPs in its status packets (docs/protocol.md); against a vendor robot the
history says the loss is not measurable.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum

import numpy as np
import numpy.typing as npt

from ocu.records import LinkEvent, LinkState, LinkStateChanged, LinkStats, SafetyEvent

# The longest window the dock offers (10 min); the history keeps this much.
DEFAULT_SPAN_S = 600.0
# What the OCU says of the uplink's loss while the robot does not echo the commands it
# applied (a vendor robot; docs/protocol.md, status version 3).
UPLINK_LOSS_UNMEASURABLE = "not measurable (the robot echoes no command sequence numbers)"
ESTOP_PREFIX = "EMERGENCY STOP"
# Nothing valid from the robot for this long: every packet it sent meanwhile was lost, and
# the round trip (measured from what arrives) is not known.
SILENT_AFTER_S = 1.0

FloatArray = npt.NDArray[np.float64]


class MarkKind(Enum):
    """What happened at a marked moment."""

    LINK_LOST = "LINK LOST"
    LINK_BACK = "link back"
    ESTOP = "E-STOP"


@dataclass(frozen=True)
class LinkMark:
    """One event on the time axis."""

    time_s: float
    kind: MarkKind
    message: str


# The figures `series` returns, by name (each an array over the samples' times).
FIGURES = (
    "command_rate_hz",
    "command_rate_setting_hz",
    "telemetry_rate_hz",
    "video_rate_hz",
    "scan_rate_hz",
    "downlink_loss",
    "uplink_loss",
    "round_trip_s",
    "jitter_s",
)


@dataclass(frozen=True)
class LinkSeries:
    """The history's figures over a time range: `times_s` and one array per figure.

    Unknown values are NaN. `frame_age_s` has one column per camera (profile order).
    """

    times_s: FloatArray
    figures: dict[str, FloatArray]
    frame_age_s: FloatArray

    def __len__(self) -> int:
        return len(self.times_s)


def _value(value: float | None) -> float:
    return math.nan if value is None else float(value)


def _silent(stats: LinkStats) -> bool:
    """Whether nothing valid has arrived from the robot lately (see SILENT_AFTER_S)."""
    age = stats.last_valid_age_s
    return age is not None and age > SILENT_AFTER_S


class LinkHistory:
    """A rolling history of link statistics and link events (see the module docstring).

    Thread-safe: the link's threads feed it, the GUI thread reads it. `cameras` is the
    number of cameras (the profile's), the columns of the frame ages.
    """

    def __init__(
        self,
        cameras: int,
        *,
        span_s: float = DEFAULT_SPAN_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.cameras = cameras
        self.span_s = span_s
        self.clock = clock
        self._lock = threading.Lock()
        # Each sample as a row: its time, the FIGURES, one frame age per camera (NaN unknown).
        self._rows: deque[tuple[float, ...]] = deque()
        self._latest: LinkStats | None = None
        self._marks: deque[LinkMark] = deque()
        self._state: LinkState | None = None
        self._version = 0

    # ---- fed by the link (its threads) -----------------------------------------------------

    def __call__(self, event: LinkEvent) -> None:
        """The link listener: statistics are sampled, state changes and e-stops marked."""
        if isinstance(event, LinkStats):
            self.add(event, self.clock())
        elif isinstance(event, LinkStateChanged):
            self.on_state(event.state, event.reason, self.clock())
        elif isinstance(event, SafetyEvent) and event.message.startswith(ESTOP_PREFIX):
            self.mark(MarkKind.ESTOP, event.message, self.clock())

    def add(self, stats: LinkStats, at: float) -> None:
        """One statistics sample taken at `at` (seconds of the history's clock)."""
        with self._lock:
            self._rows.append(self._row(stats, at))
            self._latest = stats
            self._trim(at)
            self._version += 1

    def on_state(self, state: LinkState, reason: str, at: float) -> None:
        """The link changed state: LINK LOST is marked, and so is its end."""
        with self._lock:
            previous, self._state = self._state, state
        if state is LinkState.LOST and previous is not LinkState.LOST:
            self.mark(MarkKind.LINK_LOST, reason, at)
        elif state is LinkState.CONNECTED and previous is LinkState.LOST:
            self.mark(MarkKind.LINK_BACK, reason, at)

    def mark(self, kind: MarkKind, message: str, at: float) -> None:
        """Put an event on the time axis."""
        with self._lock:
            self._marks.append(LinkMark(at, kind, message))
            self._trim(at)
            self._version += 1

    def _row(self, stats: LinkStats, at: float) -> tuple[float, ...]:
        """One sample as `series` hands it out."""
        silent = _silent(stats)
        ages = [_value(age) for age in stats.frame_age_s[: self.cameras]]
        ages += [math.nan] * (self.cameras - len(ages))
        return (
            at,
            stats.rcp_rate_hz,
            stats.send_rate_hz,
            stats.telemetry_rate_hz,
            stats.video_rate_hz,
            stats.scan_rate_hz,
            1.0 if silent else _value(stats.loss_estimate),
            math.nan if silent else _value(stats.uplink_loss),
            math.nan if silent else _value(stats.delay_s),
            math.nan if silent else _value(stats.jitter_s),
            *ages,
        )

    def _trim(self, now: float) -> None:
        limit = now - self.span_s
        while self._rows and self._rows[0][0] < limit:
            self._rows.popleft()
        while self._marks and self._marks[0].time_s < limit:
            self._marks.popleft()

    # ---- read (any thread) -----------------------------------------------------------------

    @property
    def version(self) -> int:
        """Changes whenever a sample or a mark is added (redraw only when it moved)."""
        with self._lock:
            return self._version

    def __len__(self) -> int:
        with self._lock:
            return len(self._rows)

    def latest(self) -> LinkStats | None:
        """The newest statistics, None before any."""
        with self._lock:
            return self._latest

    @property
    def uplink_measurable(self) -> bool:
        """Whether the robot echoes the commands it applied (the newest statistics say)."""
        with self._lock:
            return self._latest is not None and self._latest.uplink_loss is not None

    @property
    def uplink_loss_text(self) -> str:
        """The commands lost on the way to the robot, as the OCU can tell."""
        with self._lock:
            loss = None if self._latest is None else self._latest.uplink_loss
        return UPLINK_LOSS_UNMEASURABLE if loss is None else f"{loss:.0%}"

    def marks(self, start_s: float = -math.inf, end_s: float = math.inf) -> list[LinkMark]:
        """The events between two times (inclusive), oldest first."""
        with self._lock:
            return [m for m in self._marks if start_s <= m.time_s <= end_s]

    def series(self, start_s: float = -math.inf, end_s: float = math.inf) -> LinkSeries:
        """The figures of the samples between two times (inclusive), as arrays."""
        with self._lock:
            rows = [row for row in self._rows if start_s <= row[0] <= end_s]
        width = 1 + len(FIGURES) + self.cameras
        table = np.array(rows, dtype=np.float64).reshape(len(rows), width)
        figures = {name: table[:, 1 + column] for column, name in enumerate(FIGURES)}
        return LinkSeries(table[:, 0], figures, table[:, 1 + len(FIGURES) :])
