"""What a link reports, handed to the model by the control thread, in the order it happened.

The link's threads (receive, send) only queue: no lock of the model, no Qt. The control thread
(ocu.core.manager) drains the queue at the start of each cycle, under the model's lock, into
the model: telemetry, status, scans, statistics, the commands the link sent (odometry and the
joints' predictors need them in order with the telemetry), the link's state and extension.
LINK LOST and the link's own safety stops (its watchdog zeroed, its e-stop burst) halt the
model there, so nothing resumes when the link or the GUI comes back - and no GUI stall delays
it. A telemetry frame that arrives while the newest queued item is a telemetry frame replaces
it: a robot flooding the link cannot queue work in front of the operator's input.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from typing import TYPE_CHECKING

from ocu.link.base import Link
from ocu.records import (
    CommandSent,
    ExtensionChanged,
    LinkEvent,
    LinkState,
    LinkStateChanged,
    LinkStats,
    RobotModeReport,
    SafetyEvent,
    ScanFrame,
    StatusFrame,
    TelemetryFrame,
)

if TYPE_CHECKING:
    from ocu.console.model import ConsoleModel

log = logging.getLogger("ocu.core")

_FED = (
    TelemetryFrame,
    StatusFrame,
    ScanFrame,
    CommandSent,
    LinkStats,
    ExtensionChanged,
    LinkStateChanged,
    SafetyEvent,
    RobotModeReport,
)


class LinkFeed:
    """Queues a link's events on its threads; `read(model)` feeds them on the control thread."""

    def __init__(self, link: Link) -> None:
        self.link = link
        self._events: deque[LinkEvent] = deque()
        self._lock = threading.Lock()
        self.replaced = 0  # telemetry frames replaced by a newer one before a cycle took them
        link.subscribe(self._on_event)

    def close(self) -> None:
        """Stop listening; what is queued is dropped (idempotent)."""
        self.link.unsubscribe(self._on_event)
        with self._lock:
            self._events.clear()

    def _on_event(self, event: LinkEvent) -> None:
        if not isinstance(event, _FED):
            return
        with self._lock:
            events = self._events
            if (
                isinstance(event, TelemetryFrame)
                and events
                and isinstance(events[-1], TelemetryFrame)
            ):
                events[-1] = event
                self.replaced += 1
            else:
                events.append(event)

    def read(self, model: ConsoleModel) -> None:
        """Feed what came since the last call into `model` (the control thread, its lock held)."""
        with self._lock:
            events = list(self._events)
            self._events.clear()
        for event in events:
            try:
                feed(model, event)
            except Exception:  # one bad event must not keep the others from the model
                log.exception("feeding %s to the model failed", type(event).__name__)


def feed(model: ConsoleModel, event: LinkEvent) -> None:
    """One link event into the model."""
    if isinstance(event, TelemetryFrame):
        model.on_telemetry(event)
    elif isinstance(event, CommandSent):
        model.on_command_sent(event.command, event.sent_at)
    elif isinstance(event, StatusFrame):
        model.on_status(event)
    elif isinstance(event, ScanFrame):
        model.on_scan(event)
    elif isinstance(event, LinkStats):
        model.on_stats(event)
    elif isinstance(event, ExtensionChanged):
        model.robot.on_extension(event.active, event.reason)
    elif isinstance(event, LinkStateChanged):
        model.robot.on_link_state(event.state, event.reason)
        if event.state is LinkState.LOST:
            model.halt("link lost")
    elif isinstance(event, RobotModeReport):
        model.robot.on_robot_mode(event)
        if not event.may_move:
            # The mux's "robot stop" lock: every source stops; nothing resumes when the
            # controller takes motion again (ocu/control/mux.md).
            model.halt(f"robot controller: {event.text}", lock="robot stop")
    elif isinstance(event, SafetyEvent):
        if event.stopped:
            # The link zeroed the command by itself: the model agrees, nothing resumes.
            model.halt(event.message)
        else:
            # Nothing was stopped. Halting here would cancel a goal sent as soon as the
            # robot said it was ready again (ROS saw the mode before this event came).
            model.events.message.emit(event.message)
