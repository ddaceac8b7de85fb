"""Calls handed to the GUI thread by the inbox, and QtLink's signals emitted on that thread."""

from __future__ import annotations

import threading
from functools import partial

from PySide6.QtCore import QObject, Qt, Signal
from pytestqt.qtbot import QtBot

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.qt.inbox import gui_inbox, to_gui
from ocu.qt.link import QtLink
from ocu.sim.simulator import RobotSimulator

DEADLINE_MS = 10_000


class _Emitter(QObject):
    said = Signal(object)


def test_calls_from_many_threads_arrive_on_the_gui_thread_in_order_none_lost(
    qtbot: QtBot,
) -> None:
    inbox = gui_inbox()
    assert gui_inbox() is inbox
    gui = threading.get_ident()
    got: dict[int, list[int]] = {}
    threads_seen: set[int] = set()

    def record(writer: int, n: int) -> None:
        threads_seen.add(threading.get_ident())
        got.setdefault(writer, []).append(n)

    writers, each = 6, 3000

    def write(writer: int) -> None:
        for n in range(each):
            inbox.post(record, writer, n)

    threads = [threading.Thread(target=write, args=(w,)) for w in range(writers)]
    for thread in threads:
        thread.start()
    # The GUI thread drains while they write: a wake-up lost between the two stops delivery.
    qtbot.waitUntil(
        lambda: sum(len(v) for v in got.values()) == writers * each, timeout=DEADLINE_MS
    )
    for thread in threads:
        thread.join()
    assert threads_seen == {gui}
    assert all(got[w] == list(range(each)) for w in range(writers))


def test_to_gui_is_direct_on_the_gui_thread_and_posted_from_others(qtbot: QtBot) -> None:
    calls: list[tuple[str, int]] = []
    posted = to_gui(lambda where: calls.append((where, threading.get_ident())))
    posted("gui")
    assert calls == [("gui", threading.get_ident())]
    worker = threading.Thread(target=posted, args=("worker",))
    worker.start()
    worker.join()
    assert len(calls) == 1  # not made on the worker
    qtbot.waitUntil(lambda: len(calls) == 2, timeout=DEADLINE_MS)
    assert calls[1] == ("worker", threading.get_ident())


def test_a_signal_of_a_deleted_object_is_dropped_and_later_calls_still_run(
    qtbot: QtBot,
) -> None:
    inbox = gui_inbox()
    emitter = _Emitter()
    emit = emitter.said.emit
    emitter.deleteLater()
    qtbot.waitUntil(lambda: _deleted(emitter), timeout=DEADLINE_MS)
    after: list[int] = []

    def post_both() -> None:
        inbox.post(emit, 1)
        inbox.post(after.append, 2)

    worker = threading.Thread(target=post_both)
    worker.start()
    worker.join()
    qtbot.waitUntil(lambda: after == [2], timeout=DEADLINE_MS)


def _deleted(obj: QObject) -> bool:
    try:
        obj.objectName()
    except RuntimeError:
        return True
    return False


def test_the_links_signals_are_emitted_on_the_gui_thread(
    qtbot: QtBot, profile: RobotProfile
) -> None:
    # A direct connection runs the slot on the emitting thread: on the GUI thread now, where
    # the link's and the decoder's threads used to emit (and could deadlock on Qt's locks).
    gui = threading.get_ident()
    seen: dict[str, set[int]] = {}

    def where(name: str) -> object:
        return lambda *args: seen.setdefault(name, set()).add(threading.get_ident())

    with RobotSimulator(profile, telemetry_hz=20.0, video_fps=10.0) as sim:
        qt_link = QtLink(UdpLink(profile, sim.address))
        direct = Qt.ConnectionType.DirectConnection
        for name in (
            "telemetry_ready",
            "telemetry_received",
            "video_frame_ready",
            "video_frame_received",
            "link_state_changed",
            "stats_updated",
        ):
            getattr(qt_link, name).connect(where(name), direct)
        try:
            qt_link.start()
            qtbot.waitUntil(lambda: len(seen) == 6, timeout=DEADLINE_MS)
        finally:
            qt_link.shutdown()
    assert all(threads == {gui} for threads in seen.values()), seen


def test_every_frame_signals_follow_their_listeners_while_frames_flow(
    qtbot: QtBot, profile: RobotProfile
) -> None:
    # Listeners come and go (and are deleted) on the GUI thread while the link's and the
    # decoder's threads deliver: nothing hangs, and nothing is posted for nobody.
    with RobotSimulator(profile, telemetry_hz=50.0, video_fps=30.0) as sim:
        qt_link = QtLink(UdpLink(profile, sim.address))
        try:
            qt_link.start()
            qtbot.waitUntil(lambda: qt_link.take_telemetry() is not None, timeout=DEADLINE_MS)
            for _ in range(200):
                receiver = _Emitter()
                frames: list[object] = []
                receiver.said.connect(frames.append)
                qt_link.telemetry_received.connect(receiver.said)
                qt_link.video_frame_received.connect(receiver.said)
                qtbot.waitUntil(partial(bool, frames), timeout=DEADLINE_MS)
                receiver.deleteLater()
                qtbot.waitUntil(partial(_deleted, receiver), timeout=DEADLINE_MS)
            # Nobody listens: after the next heartbeat nothing more is posted for those signals.
            qtbot.waitUntil(lambda: not any(qt_link._wants), timeout=DEADLINE_MS)
        finally:
            qt_link.shutdown()
