"""One thread's network loop: readable transports, a wake-up socket, timers at deadlines.

The link and the simulator both run one: `step(now)` does the timed work and returns when it
next has something to do; a readable transport calls its reader; `wake()` from any thread cuts
a wait short (a command to send, a shutdown). No Qt; times are monotonic seconds.
"""

from __future__ import annotations

import contextlib
import logging
import selectors
import socket
import threading
import time
from collections.abc import Callable

log = logging.getLogger("ocu.net")

# The longest wait between two steps, whatever the deadline says: a step also polls state
# that changes without a wake-up (watchdogs).
MAX_WAIT_S = 0.1
STOP_JOIN_S = 5.0

Step = Callable[[float], float]


class SelectLoop:
    """select() over readers and a wake-up socket, calling `step` before every wait.

    `on_error` decides what an exception in a step or a reader does: return True to go on
    (the simulator counts it), False to end the loop and re-raise (the link sends zeros first).
    """

    def __init__(
        self,
        name: str,
        *,
        clock: Callable[[], float] = time.monotonic,
        on_error: Callable[[BaseException], bool] | None = None,
    ) -> None:
        self.name = name
        self.clock = clock
        self.on_error = on_error
        self._selector = selectors.DefaultSelector()
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._wake_w.setblocking(False)
        self._selector.register(self._wake_r, selectors.EVENT_READ, None)
        self._stop = threading.Event()
        self._exited = threading.Event()
        self._exited.set()
        self._thread: threading.Thread | None = None
        self._run_ident: int | None = None
        self._closed = False

    def add_reader(self, sock: socket.socket, reader: Callable[[], None]) -> None:
        """Call `reader` (on the loop's thread) whenever `sock` is readable."""
        self._selector.register(sock, selectors.EVENT_READ, reader)

    def wake(self) -> None:
        """Cut the current wait short (any thread); harmless after close()."""
        # A full wake pipe already guarantees a wake-up; a closed one means shutdown.
        with contextlib.suppress(OSError):
            self._wake_w.send(b"\0")

    @property
    def stopping(self) -> bool:
        """Whether stop() was asked for."""
        return self._stop.is_set()

    @property
    def running(self) -> bool:
        """Whether the loop is inside run()."""
        return not self._exited.is_set()

    def start(self, step: Step) -> None:
        """Run the loop in a named daemon thread."""
        if self._thread is not None:
            return
        self._exited.clear()
        self._thread = threading.Thread(target=self.run, args=(step,), name=self.name, daemon=True)
        self._thread.start()

    def run(self, step: Step) -> None:
        """Run the loop in the calling thread until stop()."""
        self._exited.clear()
        self._run_ident = threading.get_ident()
        try:
            while not self._stop.is_set():
                try:
                    deadline = step(self.clock())
                    timeout = min(max(deadline - self.clock(), 0.0), MAX_WAIT_S)
                    for key, _ in self._selector.select(timeout):
                        if key.data is None:
                            self._drain_wake()
                        elif not self._stop.is_set():
                            key.data()
                except Exception as err:
                    if self._stop.is_set():
                        break
                    if self.on_error is None or not self.on_error(err):
                        raise
        finally:
            self._exited.set()

    def stop(self, timeout_s: float = STOP_JOIN_S) -> bool:
        """End the loop and wait for it; True if it ended in time. Safe to call twice."""
        self._stop.set()
        self.wake()
        if threading.get_ident() == self._run_ident and not self._exited.is_set():
            return True  # asked from inside the loop: it ends after this step
        ended = self._exited.wait(timeout_s)
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout_s)
            ended = ended and not thread.is_alive()
        if not ended:
            log.error("%s loop did not stop within %.1f s", self.name, timeout_s)
        return ended

    def close(self) -> None:
        """Release the selector and the wake-up socket (after stop())."""
        if self._closed:
            return
        self._closed = True
        self._selector.close()
        self._wake_r.close()
        self._wake_w.close()

    def _drain_wake(self) -> None:
        try:
            while self._wake_r.recv(4096):
                pass
        except BlockingIOError:
            pass
