"""Cyclic garbage holding QObjects is collected in the GUI thread, never in a worker's."""

from __future__ import annotations

import gc
import threading
from typing import ClassVar

from PySide6.QtCore import QObject, QTimer
from pytestqt.qtbot import QtBot

from ocu.qt.collector import GuiThreadCollector, pin_garbage_collection


class _Panel:
    """A closed panel: a QObject in a reference cycle; notes the thread that frees it."""

    freed_in: ClassVar[list[str]] = []

    def __init__(self) -> None:
        self.timer = QTimer()
        self.timer.setInterval(1000)
        self.me = self  # the cycle: only the cyclic collector frees it

    def __del__(self) -> None:
        _Panel.freed_in.append(threading.current_thread().name)


def test_garbage_made_busy_by_a_worker_is_collected_in_the_gui_thread(qtbot: QtBot) -> None:
    collector = pin_garbage_collection()
    assert pin_garbage_collection() is collector  # one per application
    assert not gc.isenabled()
    _Panel.freed_in.clear()
    _Panel()

    # A worker allocating past every threshold (what the link thread does all day); its
    # containers stay alive, so the net count the interpreter compares is what grows.
    made: list[list[object]] = []

    def allocate() -> None:
        made.extend([] for _ in range(collector.threshold[0] * 3))

    worker = threading.Thread(target=allocate, name="ocu-test-allocator")
    worker.start()
    worker.join(30.0)
    assert not worker.is_alive()
    assert _Panel.freed_in == []  # nothing collected in the worker
    qtbot.waitUntil(lambda: bool(_Panel.freed_in), timeout=5000)
    assert _Panel.freed_in == [threading.main_thread().name]
    assert sum(collector.collections) > 0
    made.clear()


def test_the_collector_refuses_other_threads_and_gives_collection_back(qtbot: QtBot) -> None:
    own = GuiThreadCollector(interval_ms=10_000)
    results: list[int] = []
    gc.collect()
    _Panel()  # garbage to collect
    # Allocations push generation 0 past its threshold; a call from a worker is ignored.
    allocated = [[object()] for _ in range(own.threshold[0] * 2)]
    worker = threading.Thread(target=lambda: results.append(own.check()), name="ocu-test")
    worker.start()
    worker.join(10.0)
    assert results == [0]
    assert own.check() > 0  # the owner collects
    del allocated
    shared = pin_garbage_collection()
    own.stop()
    assert gc.isenabled()  # stop() hands collection back ...
    gc.disable()  # ... which the session's collector (pinned for the whole run) takes again
    assert pin_garbage_collection() is shared
    own.deleteLater()
    assert isinstance(shared, QObject)
