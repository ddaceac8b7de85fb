"""Python's cyclic garbage collector, run in the GUI thread only (pyqtgraph's GarbageCollector).

CPython runs a collection in whichever thread crosses the allocation threshold: in the
console that is as often the link's, the gamepad's, the replay's or the simulator's thread as
the GUI thread. A collection there frees whatever cyclic garbage exists at that moment, and
closed panels, dialogs and windows are cyclic garbage holding QObjects (signal connections
to bound methods make the cycles). A QObject destroyed outside its thread is undefined in
Qt: timers cannot be stopped from another thread, and the destructor takes Qt's locks while
that thread holds the GIL, which is how a test run hung for the CI's whole budget (the
replay thread inside a collection, the GUI thread waiting for the GIL).

So automatic collection is switched off and a timer in the GUI thread collects, with the
generation logic of the interpreter's own thresholds; allocations in other threads only
raise the counters. The first installation wins; later calls return the same collector.
"""

from __future__ import annotations

import gc
import logging

from PySide6.QtCore import QCoreApplication, QObject, QThread, QTimer

log = logging.getLogger(__name__)

# Often enough that generation 0 stays near its threshold at the console's allocation rate
# (telemetry at 30 Hz, video at 4 x 30 frames/s allocate a few thousand objects a second).
CHECK_INTERVAL_MS = 100
_OBJECT_NAME = "ocu-gui-garbage-collector"


class GuiThreadCollector(QObject):
    """Collects cyclic garbage on a timer in the thread that owns it; automatic GC off."""

    def __init__(self, parent: QObject | None = None, interval_ms: int = CHECK_INTERVAL_MS):
        super().__init__(parent)
        self.setObjectName(_OBJECT_NAME)
        threshold = gc.get_threshold()
        # With automatic collection already off (someone else pins it), keep the defaults.
        self.threshold = threshold if threshold[0] > 0 else (700, 10, 10)
        self.collections = [0, 0, 0]
        gc.disable()
        self._timer = QTimer(self)
        self._timer.setInterval(interval_ms)
        self._timer.timeout.connect(self.check)
        self._timer.start()

    def check(self) -> int:
        """Collect the generations whose counters passed their thresholds; objects freed."""
        if QThread.currentThread() is not self.thread():
            # Only the owning thread collects; a call from elsewhere is a bug, not a crash.
            log.error("garbage collection asked for outside the GUI thread; ignored")
            return 0
        count0, count1, count2 = gc.get_count()
        if count0 <= self.threshold[0]:
            return 0
        generation = 0
        if count1 > self.threshold[1]:
            generation = 1
            if count2 > self.threshold[2]:
                generation = 2
        self.collections[generation] += 1
        return gc.collect(generation)

    def stop(self) -> None:
        """Give collection back to the interpreter (automatic, any thread)."""
        self._timer.stop()
        self.setObjectName("")  # the next pin_garbage_collection() makes a new one
        gc.enable()


def pin_garbage_collection() -> GuiThreadCollector:
    """The application's collector, made on first call (needs the QCoreApplication)."""
    app = QCoreApplication.instance()
    if app is None:
        raise RuntimeError("pinning garbage collection needs a QCoreApplication")
    existing = app.findChild(GuiThreadCollector, _OBJECT_NAME)
    if isinstance(existing, GuiThreadCollector):
        return existing
    if QThread.currentThread() is not app.thread():
        raise RuntimeError("garbage collection must be pinned from the GUI thread")
    return GuiThreadCollector(app)
