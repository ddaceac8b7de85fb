"""The console model bound to a link: the wiring, in one place, between a QtLink and the model.

Link events go into the model's robot state — telemetry at most ~30 times a second, from the
link's one-frame mailbox, so a robot flooding the link cannot queue work in front of the
operator's keys — and into its navigator: status (the IMU heading), range scans and every
command the link sent (odometry). The model's command goes to the link whenever it changes,
and nothing is ever read back from the link. A read-only link (a replay) gets no commands.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QObject, QTimer, SignalInstance

from ocu.console.events import Event
from ocu.console.model import ConsoleModel
from ocu.qt.link import QtLink
from ocu.records import CameraRequest, CommandSent, LinkState, LinkStats, ScanFrame, StatusFrame

# Telemetry reaches the model at most this often (about 30 Hz).
VIEW_PERIOD_MS = 33


class ConsoleBinding(QObject):
    """Feeds `model` from `link` and `link` from `model` until unbind()."""

    def __init__(
        self,
        model: ConsoleModel,
        link: QtLink,
        parent: QObject | None = None,
        *,
        control_thread: bool = False,
    ) -> None:
        super().__init__(parent)
        self.model = model
        self.link = link
        self._last_take_at = 0.0
        self._bound = True
        # Methods of this QObject: the signals are emitted on the GUI thread (ocu.qt.inbox).
        # With a control thread (the console's), that thread feeds the model from the link
        # itself (ocu.core.feed) and this binding only sends the model's command.
        self._wiring: tuple[tuple[SignalInstance, Callable[..., None]], ...] = (
            (link.telemetry_ready, self._on_telemetry_ready),
            (link.link_state_changed, self._on_link_state),
            (link.stats_updated, self._on_stats),
            (link.status_received, self._on_status),
            (link.extension_changed, self._on_extension),
            (link.scan_received, self._on_scan),
            (link.command_sent, self._on_command_sent),
        )
        if control_thread:
            self._wiring = ()
        for signal, slot in self._wiring:
            signal.connect(slot)
        events = model.events
        # What goes to the robot: nothing for a read-only link (a replay).
        self._commands: tuple[tuple[Event[Any], Callable[..., None]], ...] = ()
        if not link.read_only:
            self._commands = (
                (events.command_changed, self._push_command),
                (events.stream_request_changed, self._push_streams),
                (events.estop_requested, self._estop),
            )
        for event, callback in self._commands:
            event.connect(callback, direct=True)  # on the thread that changed the command
        if not link.read_only:
            link.link.set_command(model.command())
            link.link.set_stream_request(model.stream_request)
        # Takes the newest frame within one period when telemetry came faster than that.
        self._timer = QTimer(self)
        self._timer.setInterval(VIEW_PERIOD_MS)
        self._timer.timeout.connect(self.take_telemetry)
        if not control_thread:
            self._timer.start()

    def take_telemetry(self) -> None:
        """Hand the newest telemetry frame, if any came, to the model."""
        self._last_take_at = time.monotonic()
        frame = self.link.take_telemetry()
        if frame is not None and self._bound:
            self.model.on_telemetry(frame)

    def _on_telemetry_ready(self) -> None:
        if (time.monotonic() - self._last_take_at) * 1000.0 >= VIEW_PERIOD_MS:
            self.take_telemetry()

    def _on_link_state(self, state: LinkState, reason: str) -> None:
        if self._bound:
            self.model.robot.on_link_state(state, reason)

    def _on_stats(self, stats: LinkStats) -> None:
        if self._bound:
            self.model.on_stats(stats)

    def _on_status(self, status: StatusFrame) -> None:
        if self._bound:
            self.model.on_status(status)

    def _on_scan(self, scan: ScanFrame) -> None:
        if self._bound:
            self.model.on_scan(scan)

    def _on_command_sent(self, sent: CommandSent) -> None:
        # What went on the wire, the link's own zeros included: odometry integrates it.
        if self._bound:
            self.model.on_command_sent(sent.command, sent.sent_at)

    def _on_extension(self, active: bool, reason: str) -> None:
        if self._bound:
            self.model.robot.on_extension(active, reason)

    def _push_command(self) -> None:
        self.link.link.set_command(self.model.command())

    def _push_streams(self, streams: tuple[CameraRequest, ...]) -> None:
        self.link.link.set_stream_request(streams)

    def _estop(self, reason: str) -> None:
        self.link.link.emergency_stop(reason)

    def unbind(self) -> None:
        """Stop the wiring (the link is shutting down); idempotent."""
        if not self._bound:
            return
        self._bound = False
        self._timer.stop()
        for signal, slot in self._wiring:
            signal.disconnect(slot)
        for event, callback in self._commands:
            event.disconnect(callback)
