"""Shared fixtures: offscreen Qt, the console's priority, the shipped profile, no thread left
running."""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
# PyOpenGL picks its platform at first import; offscreen Qt has no GL, so render via OSMesa.
from ocu.render.platform import offscreen_gl_mode

os.environ.setdefault("PYOPENGL_PLATFORM", offscreen_gl_mode())

import pytest

from ocu.priority import nice_from_env, raise_priority
from ocu.profile import RobotProfile, load_profile

# The console's own scheduling priority for the whole run, asked for before any thread starts,
# as `ocu` and `ocu-ros` do first thing (ocu.priority; $OCU_NICE=0 runs the suite at the
# default priority, as an unprivileged user's console runs). The simulators the tests start
# as processes run at the default priority, as they do beside the console.
raise_priority(nice_from_env())

_started_qthreads: list[object] = []


@pytest.fixture(scope="session")
def profile() -> RobotProfile:
    """The shipped Engineer profile."""
    return load_profile()


@pytest.fixture(scope="session", autouse=True)
def _gui_thread_collector(qapp: object) -> Iterator[object]:
    """The console's own policy for the whole run: cyclic garbage (closed windows, panels,
    their timers) is collected in the GUI thread only, never in a link or simulator thread."""
    from ocu.qt.collector import pin_garbage_collection

    collector = pin_garbage_collection()
    yield collector
    collector.stop()


@pytest.fixture(autouse=True)
def _collect_in_the_gui_thread(
    _gui_thread_collector: object, request: pytest.FixtureRequest
) -> Iterator[None]:
    """Tests that never spin the event loop still have their garbage collected, here. After a
    Qt test all of it: a closed console left for the next test to collect stalled that test's
    GUI thread for 0.5 s (the link's watchdog then zeroed a tracking run)."""
    yield
    if "qtbot" in request.fixturenames:
        import gc

        gc.collect()
    else:
        _gui_thread_collector.check()  # type: ignore[attr-defined]


@pytest.fixture(autouse=True)
def _no_thread_left_running() -> Iterator[None]:
    """Fail a test that leaves a QThread or an ocu-* Python thread running (napari's habit)."""
    before = {t.ident for t in threading.enumerate()}
    yield
    leftovers = [
        t.name
        for t in threading.enumerate()
        if t.ident not in before and t.name.startswith("ocu") and t.is_alive()
    ]
    for thread in list(_started_qthreads):
        if thread.isRunning():  # type: ignore[attr-defined]
            leftovers.append(f"QThread {thread.objectName()}")  # type: ignore[attr-defined]
    _started_qthreads.clear()
    assert not leftovers, f"threads left running: {leftovers}"


def _track_qthreads() -> None:
    """Record every QThread started, so the fixture above can check it stopped."""
    try:
        from PySide6.QtCore import QThread
    except ImportError:
        return
    original = QThread.start

    def start(self: QThread, *args: object) -> None:
        _started_qthreads.append(self)
        original(self, *args)  # type: ignore[arg-type]

    QThread.start = start  # type: ignore[method-assign, assignment]


_track_qthreads()
