"""Zeros last, however the process ends: the live links' own hooks, not Qt's teardown.

An orderly quit shuts the console's link down (its zero burst is the last thing on the wire).
Everything else that ends the process while it can still run Python is caught here:

- Python's own exit that skips the console's shutdown (an unhandled exception in the main
  thread, `sys.exit` from anywhere): an `atexit` hook shuts every live link down.
- An unhandled exception in any thread (`sys.excepthook`, `threading.excepthook`, which also
  see exceptions in Qt slots): every live link sends its e-stop burst, and the console halts
  on the link's safety event, so nothing resumes.
- A library about to call C's `exit()` (Xlib's fatal I/O error handler when the X server
  dies): the caller runs `shutdown_live_links` first (ocu.app hooks the X server's loss).

Signals (SIGINT, SIGTERM, SIGHUP, SIGQUIT) quit the console in order (ocu.app). A SIGKILL or
a segfault leaves no chance: the robot's own watchdog stops it.
"""

from __future__ import annotations

import atexit
import logging
import sys
import threading
from types import TracebackType

from ocu.link.live import live_links

log = logging.getLogger("ocu.link")


def stop_live_links(reason: str) -> None:
    """Every live link sends its e-stop burst now (any thread); one failing spares the others."""
    for link in live_links():
        try:
            link.emergency_stop(reason)
        except Exception:
            log.exception("e-stop of %s failed", link.description)


def shutdown_live_links(reason: str) -> None:
    """Shut every live link down now: its zero burst is the last thing it sends."""
    links = live_links()
    if links:
        log.warning("%s: shutting the link down (zeros last)", reason)
    for link in links:
        try:
            link.shutdown()
        except Exception:
            log.exception("shutdown of %s failed", link.description)


class ExitGuard:
    """The hooks of the module docstring, installed together; `uninstall` restores the old ones."""

    def __init__(self) -> None:
        self._installed = False
        self._previous_excepthook = sys.excepthook
        self._previous_thread_hook = threading.excepthook

    def install(self) -> ExitGuard:
        """Install the hooks (idempotent); returns self."""
        if self._installed:
            return self
        self._installed = True
        self._previous_excepthook = sys.excepthook
        self._previous_thread_hook = threading.excepthook
        sys.excepthook = self._excepthook
        threading.excepthook = self._thread_excepthook
        atexit.register(self._at_exit)
        return self

    def uninstall(self) -> None:
        """Put the previous hooks back."""
        if not self._installed:
            return
        self._installed = False
        sys.excepthook = self._previous_excepthook
        threading.excepthook = self._previous_thread_hook
        atexit.unregister(self._at_exit)

    def __enter__(self) -> ExitGuard:
        return self.install()

    def __exit__(self, *exc: object) -> None:
        self.uninstall()

    def _excepthook(
        self,
        kind: type[BaseException],
        value: BaseException,
        traceback: TracebackType | None,
    ) -> None:
        stop_live_links(f"unhandled {kind.__name__} in the main thread")
        self._previous_excepthook(kind, value, traceback)

    def _thread_excepthook(self, args: threading.ExceptHookArgs) -> None:
        if args.exc_type is SystemExit:  # a thread that ends itself on purpose
            self._previous_thread_hook(args)
            return
        name = args.thread.name if args.thread is not None else "a thread"
        stop_live_links(f"unhandled {args.exc_type.__name__} in thread {name}")
        self._previous_thread_hook(args)

    def _at_exit(self) -> None:
        shutdown_live_links("the program is exiting")
