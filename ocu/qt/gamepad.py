"""The game controller in Qt: the poll thread's states and events delivered on the GUI thread.

`QtGamepad` owns the `PadPoller` ("ocu-gamepad" thread) and hands what it reads to the
`GamepadTeleop` on the GUI thread, where the console model lives. The poll thread posts one
high-priority event when it has something new and none is waiting; the GUI thread then
handles the pad's events (connected, unplugged, errors) in order and takes the newest state
(with every press since the last): a busy GUI takes the newest state instead of a queue of
old ones, and takes it before the repaints and telemetry that wait with it.
A watchdog on the GUI thread reads the poll thread's last poll time: silent for the
mapping's `stall_timeout_ms` while a pad is in use, and the pad's motion stops.
"""

from __future__ import annotations

import threading
from collections import deque

from PySide6.QtCore import QCoreApplication, QEvent, QObject, Qt, QTimer

from ocu.gamepad.core_pad import WATCHDOG_CHECKS, deliver, watch_poller
from ocu.gamepad.pad import PadEvent
from ocu.gamepad.poller import PadPoller
from ocu.gamepad.teleop import GamepadTeleop

# "The poll thread has something new": posted at high priority, so it is handled before the
# other events that wait (telemetry, repaints) as soon as the GUI thread is free.
READY = QEvent.Type(QEvent.registerEventType())
HIGH_PRIORITY = Qt.EventPriority.HighEventPriority.value


class QtGamepad(QObject):
    """Runs the poller and feeds the teleop on the GUI thread; `shutdown()` stops both."""

    def __init__(
        self, teleop: GamepadTeleop, parent: QObject | None = None, *, direct: bool = False
    ) -> None:
        super().__init__(parent)
        # direct: the poll thread hands its events and states to the teleop itself - the
        # console's control core guards the teleop with the model's lock and hands its events
        # to the GUI thread - so a busy GUI thread (a 3D redraw, video) cannot delay the pad.
        self.direct = direct
        self.setObjectName("ocu-qt-gamepad")
        self.teleop = teleop
        mapping = teleop.mapping
        self.stall_timeout_s = mapping.stall_timeout_s
        self.poller = PadPoller(mapping.poll_hz, self._on_state_thread, self._on_event_thread)
        # Filled on the poll thread, emptied on the GUI thread, in order: a pad's events
        # (connected first) are handled before its newest state.
        self._events: deque[PadEvent] = deque()
        self._posted = False
        self._post_lock = threading.Lock()
        self._watchdog = QTimer(self)
        self._watchdog.setInterval(max(5, round(1000 * self.stall_timeout_s / WATCHDOG_CHECKS)))
        self._watchdog.timeout.connect(self.check_stall)
        self._started = False

    def start(self) -> None:
        """Start polling."""
        if self._started:
            return
        self._started = True
        self.teleop.start()
        self.poller.start()
        self._watchdog.start()

    def shutdown(self) -> None:
        """Stop polling; the pad's motion stops. Idempotent."""
        if not self._started:
            return
        self._started = False
        self._watchdog.stop()
        self.poller.stop()
        if self.teleop.info is not None:
            self.teleop.on_disconnected("closed with the console")

    # ---- the poll thread ---------------------------------------------------------------------

    def _on_state_thread(self) -> None:
        if self.direct:
            self._take()
            return
        self._post()

    def _on_event_thread(self, event: PadEvent) -> None:
        self._events.append(event)
        if self.direct:
            self._take()
            return
        self._post()

    def _post(self) -> None:
        # One "ready" event at most waits in the GUI thread's queue.
        with self._post_lock:
            if self._posted:
                return
            self._posted = True
        QCoreApplication.postEvent(self, QEvent(READY), HIGH_PRIORITY)

    # ---- the GUI thread (and the poll thread when direct) -------------------------------------

    def customEvent(self, event: QEvent) -> None:
        """The poll thread has something new: its events in order, then the newest state."""
        if event.type() != READY:
            super().customEvent(event)
            return
        with self._post_lock:
            self._posted = False
        self._take()

    def _take(self) -> None:
        # The pad's events in order, then its newest state (the GUI thread, or the poll
        # thread when direct).
        while self._events:
            self._on_event(self._events.popleft())
        state = self.poller.take()
        if state is not None and self._started:
            self.teleop.on_state(state)

    def _on_event(self, event: PadEvent) -> None:
        if self._started:
            deliver(self.teleop, event)

    def check_stall(self) -> None:
        """The watchdog: a poll thread silent too long stops the pad's motion."""
        watch_poller(self.teleop, self.poller, self.stall_timeout_s)
