"""How the console's process runs its window and ends: stop signals, zeros last (ocu.app).

- `STOP` (`StopSignals`): SIGINT, SIGTERM, SIGHUP and SIGQUIT quit the console in order, from
  the start of `ocu.app.main` on;
- `last_zeros_guard`: the live links send zeros last however the process ends, an X server
  that dies included;
- `run_window`: show the console and run Qt's event loop until quit, then shut it down.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import logging
import signal
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from PySide6.QtWidgets import QApplication

    from ocu.windows.main_window import MainWindow

log = logging.getLogger("ocu")

SIGNAL_POLL_MS = 100
# Each quits the console in order, zeros last: Ctrl-C, kill, a closed terminal or a dropped
# SSH session, Ctrl-\\.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGQUIT)


@contextlib.contextmanager
def last_zeros_guard() -> Iterator[None]:
    """The live links send zeros last however the process ends (ocu.link.guard), including
    an X server that dies: Xlib ends the process from its fatal I/O error handler."""
    from ocu.link.guard import ExitGuard, shutdown_live_links

    with ExitGuard(), on_x_server_loss(lambda: shutdown_live_links("X server connection lost")):
        yield


XIOErrorHandler = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p)


@contextlib.contextmanager
def on_x_server_loss(action: Callable[[], None]) -> Iterator[None]:
    """Run `action` when Xlib reports the X connection lost, before it exits the process.

    Xlib calls its I/O error handler and then C's exit(), which skips Python's atexit hooks
    and Qt's teardown; this handler runs first, then the one it replaced (Xlib's default
    prints the "XIO: fatal IO error" line). Nothing to do on other platforms (offscreen).
    """
    from PySide6.QtGui import QGuiApplication

    xlib = _xlib() if QGuiApplication.platformName() == "xcb" else None
    if xlib is None:
        yield
        return
    previous: list[int | None] = [None]

    def handler(display: int | None) -> int:
        try:
            action()
        except Exception:
            log.exception("X connection lost: the last-chance action failed")
        chained = previous[0]
        return XIOErrorHandler(chained)(display) if chained else 0

    callback = XIOErrorHandler(handler)
    previous[0] = xlib.XSetIOErrorHandler(callback)
    try:
        yield
    finally:
        xlib.XSetIOErrorHandler(XIOErrorHandler(previous[0] or 0))


def _xlib() -> ctypes.CDLL | None:
    """libX11 as loaded by Qt's xcb plugin (the same library instance), or None."""
    try:
        xlib = ctypes.CDLL(ctypes.util.find_library("X11") or "libX11.so.6")
    except OSError:
        return None
    xlib.XSetIOErrorHandler.restype = ctypes.c_void_p
    xlib.XSetIOErrorHandler.argtypes = [XIOErrorHandler]
    return xlib


def run_window(app: QApplication, window: MainWindow, quit_after_s: float | None) -> int:
    """Show the console, run Qt's event loop until quit (signals, --quit-after), shut down."""
    from PySide6.QtCore import QTimer

    app.aboutToQuit.connect(window.shutdown)
    STOP.install()  # main() has done it already; a caller that did not gets it here
    STOP.looping = True

    def quit_on_signal() -> None:
        if STOP.received:
            log.info("%s received, quitting", signal.Signals(STOP.received[0]).name)
            app.quit()

    pulse = QTimer()
    pulse.start(SIGNAL_POLL_MS)
    pulse.timeout.connect(quit_on_signal)
    # A signal that came while the window was being built quits at the loop's first turn.
    QTimer.singleShot(0, quit_on_signal)
    if quit_after_s is not None:
        QTimer.singleShot(int(quit_after_s * 1000), app.quit)
    if window.layout_restored:
        window.show()
    else:
        # First run: the whole screen for the cockpit (also without a window manager).
        screen = window.screen()
        if screen is not None:
            window.resize(screen.availableGeometry().size())
        window.showMaximized()
    code = app.exec()
    window.shutdown()
    from ocu.windows.teardown import dispose

    dispose(window)
    pulse.stop()
    STOP.looping = False
    STOP.received.clear()  # handled
    return code


class StopSignals:
    """SIGINT, SIGTERM, SIGHUP and SIGQUIT quit the console in order, from the start of main().

    Python runs a signal handler between any two bytecodes of the main thread, e.g. in the
    middle of a send that holds the link's lock: the handler only notes the signal, and a
    short timer of the event loop (which also lets Python see the signal at all) quits Qt,
    so the window's shutdown sends zeros last. A signal that comes before the loop runs
    (while the simulator starts or the window is built, with the link perhaps already
    sending) is noted the same way and quits at the loop's first turn. A second one before
    the loop runs ends a start that hangs: SystemExit, whose atexit hook still shuts the
    live links down (ocu.link.guard).
    """

    def __init__(self) -> None:
        self.received: list[int] = []
        self.looping = False
        self._installed = False

    def install(self) -> None:
        """Catch the stop signals (main thread only; idempotent)."""
        if self._installed:
            return
        self._installed = True
        for sig in STOP_SIGNALS:
            signal.signal(sig, self._handle)

    def _handle(self, signum: int, _frame: object) -> None:
        self.received.append(signum)
        if len(self.received) > 1 and not self.looping:
            raise SystemExit(128 + signum)


STOP = StopSignals()
