"""The game controller in Qt: the poll thread's states and events delivered on the GUI thread.

`QtGamepad` owns the `PadPoller` ("ocu-gamepad" thread) and hands what it reads to the
`GamepadTeleop` on the GUI thread, where the console model lives. States go through a
one-state mailbox: the poll thread signals only when the mailbox was empty, so a busy GUI
takes the newest state (with every press since the last) instead of a queue of old ones.
A watchdog on the GUI thread reads the poll thread's last poll time: silent for the
mapping's `stall_timeout_ms` while a pad is in use, and the pad's motion stops.
"""

from __future__ import annotations

import threading
import time

from PySide6.QtCore import QObject, QTimer, Signal

from ocu.gamepad.pad import (
    PadConnected,
    PadDisconnected,
    PadError,
    PadEvent,
    PadUnavailable,
    PadUnsupported,
)
from ocu.gamepad.poller import PadPoller
from ocu.gamepad.teleop import GamepadTeleop, PadStatus

# The watchdog looks this many times per stall timeout.
WATCHDOG_CHECKS = 4


class QtGamepad(QObject):
    """Runs the poller and feeds the teleop on the GUI thread; `shutdown()` stops both."""

    state_ready = Signal()
    pad_event = Signal(object)

    def __init__(self, teleop: GamepadTeleop, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.setObjectName("ocu-qt-gamepad")
        self.teleop = teleop
        mapping = teleop.mapping
        self.stall_timeout_s = mapping.stall_timeout_s
        self.poller = PadPoller(mapping.poll_hz, self._on_state_thread, self.pad_event.emit)
        self._queued = False
        self._queue_lock = threading.Lock()
        # Methods of this QObject: emitted on the poll thread, run on the GUI thread.
        self.state_ready.connect(self._take_state)
        self.pad_event.connect(self._on_event)
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

    def _on_state_thread(self) -> None:
        # The poll thread: one signal at most waits in the GUI's queue.
        with self._queue_lock:
            if self._queued:
                return
            self._queued = True
        self.state_ready.emit()

    def _take_state(self) -> None:
        with self._queue_lock:
            self._queued = False
        state = self.poller.take()
        if state is not None and self._started:
            self.teleop.on_state(state)

    def _on_event(self, event: PadEvent) -> None:
        if not self._started:
            return
        teleop = self.teleop
        if isinstance(event, PadConnected):
            teleop.on_connected(event.info)
        elif isinstance(event, PadDisconnected):
            teleop.on_disconnected(event.reason)
        elif isinstance(event, PadError):
            teleop.on_error(event.message)
        elif isinstance(event, PadUnavailable):
            teleop.on_unavailable(event.message)
        elif isinstance(event, PadUnsupported):
            teleop.events.message.emit(
                f"joystick '{event.name}' is not a game controller SDL knows: it is not used "
                "(give SDL its mapping in SDL_GAMECONTROLLERCONFIG)"
            )

    def check_stall(self) -> None:
        """The watchdog: a poll thread silent too long stops the pad's motion."""
        if not self.poller.running:
            if self.teleop.status is not PadStatus.UNAVAILABLE:
                self.teleop.on_stalled("the gamepad poll thread ended")
            return
        last = self.poller.last_poll_at
        if last is None:  # SDL still starting: no pad can be in use yet
            return
        silent_s = time.monotonic() - last
        if silent_s > self.stall_timeout_s:
            self.teleop.on_stalled(f"gamepad poll thread silent for {1000 * silent_s:.0f} ms")
        else:
            self.teleop.on_polling()
