"""Calls handed from any thread to the GUI thread without calling Qt on the calling thread.

Why not a queued signal: PySide calls Qt with the GIL held (only functions marked
`allow-thread` release it; neither `emit` nor `isSignalConnected` is). Emitting across threads
takes a Qt mutex (the receiver's, from a pool of 131 shared by every QObject); the GUI thread
can hold such a mutex while it needs the GIL - Qt may call `disconnectNotify` "with a QObject
internal mutex locked", and PySide's override of it takes the GIL. A worker thread that holds
the GIL and waits for that mutex, and the GUI thread that holds the mutex and waits for the
GIL, wait for ever: a CI run hung for 150 s that way (the video decoder thread in
`isSignalConnected`, the GUI thread in `qWait`).

So a thread hands the GUI thread plain Python calls: `post(fn, *args)` appends to a deque and,
when nothing is waiting yet, writes one byte to a socket pair (the write releases the GIL and
takes no Qt lock). A `QSocketNotifier` on the GUI thread wakes, empties the deque in order and
makes the calls there, where emitting a signal is a direct call. One inbox serves the
application (`gui_inbox()`); calls are made in the order they were posted, from every thread.
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading
from collections import deque
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QCoreApplication, QObject, QSocketNotifier, QThread

from ocu.console.events import register_dispatcher

log = logging.getLogger(__name__)

_OBJECT_NAME = "ocu-gui-inbox"


class GuiInbox(QObject):
    """Calls posted from any thread, made on the thread that owns the inbox (the GUI's)."""

    def __init__(self, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.setObjectName(_OBJECT_NAME)
        self._reader, self._writer = socket.socketpair()
        self._reader.setblocking(False)
        self._writer.setblocking(False)
        self._calls: deque[tuple[Callable[..., object], tuple[Any, ...]]] = deque()
        self._lock = threading.Lock()
        self._woken = False
        self._closed = False
        self.owner = threading.get_ident()
        self.posted = 0
        self.wakeups = 0
        self._notifier = QSocketNotifier(self._reader.fileno(), QSocketNotifier.Type.Read, self)
        self._notifier.activated.connect(self._drain)
        # The console's events (ocu.console.events) hand this thread its callbacks the same way.
        register_dispatcher(self.owner, self.post)

    def post(self, fn: Callable[..., object], *args: Any) -> None:
        """Make `fn(*args)` on the GUI thread, after every call posted before it (any thread)."""
        if self._closed:
            return
        self._calls.append((fn, args))
        with self._lock:
            self.posted += 1
            if self._woken:
                return
            self._woken = True
        # Full (a byte is waiting anyway) or closed with the application: nothing to wake.
        with contextlib.suppress(OSError):
            self._writer.send(b"\0")

    def drain(self) -> int:
        """Make every call waiting now (the GUI thread); how many were made."""
        # The wake-up bytes first, then the flag: a call posted in between finds the flag set
        # and writes nothing, but it is in the deque already and is made below.
        try:
            while self._reader.recv(4096):
                pass
        except (BlockingIOError, OSError):
            pass
        with self._lock:
            self._woken = False
        made = 0
        # Only the calls waiting now: one that posts again is made on the next wake-up.
        for _ in range(len(self._calls)):
            fn, args = self._calls.popleft()
            made += 1
            try:
                fn(*args)
            except RuntimeError as err:
                # A signal of a QObject deleted since the call was posted: nobody to tell.
                if "already deleted" not in str(err):
                    log.exception("a call handed to the GUI thread failed")
            except Exception:
                log.exception("a call handed to the GUI thread failed")
        return made

    def _drain(self) -> None:
        self.wakeups += 1
        self.drain()

    def close(self) -> None:
        """Drop what waits and stop taking calls (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._notifier.setEnabled(False)
        self._calls.clear()
        self._reader.close()
        self._writer.close()


def gui_inbox() -> GuiInbox:
    """The application's inbox, made on first use (from the GUI thread)."""
    app = QCoreApplication.instance()
    if app is None:
        raise RuntimeError("a QCoreApplication is needed before the GUI inbox")
    existing = app.findChild(GuiInbox, _OBJECT_NAME)
    if isinstance(existing, GuiInbox):
        return existing
    if QThread.currentThread() is not app.thread():
        raise RuntimeError("the GUI inbox must be made on the GUI thread")
    return GuiInbox(app)


def to_gui(fn: Callable[..., object]) -> Callable[..., None]:
    """`fn` as a callable any thread may call, made on the GUI thread (as Qt's AutoConnection:
    at once when called there, posted to the inbox when called on another thread)."""
    inbox = gui_inbox()
    owner = inbox.owner

    def on_gui(*args: Any) -> None:
        if threading.get_ident() == owner:
            fn(*args)
        else:
            inbox.post(fn, *args)

    return on_gui
