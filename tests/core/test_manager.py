"""The control core without Qt: the guarded handle, the cycle's order, the watchdogs, timing."""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence

import pytest

from ocu.console.events import Event, hand_over, register_dispatcher
from ocu.console.model import ConsoleModel
from ocu.core.guard import Guarded, unguarded
from ocu.core.manager import ControllerManager
from ocu.profile import RobotProfile
from ocu.records import CameraRequest, Command

DEADLINE_S = 10.0


class Clock:
    """A clock the test moves (the manager's cycle() takes the time it is given)."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


class Beats:
    """The hardware: records the cycle's calls (and whether the model's lock was held)."""

    def __init__(self, lock: threading.RLock | None = None) -> None:
        self.count = 0
        self.lock = lock
        self.calls: list[tuple[str, bool]] = []
        self.written: list[Command] = []

    def _held(self) -> bool:
        return self.lock is not None and bool(self.lock._is_owned())  # type: ignore[attr-defined]

    def read(self, model: ConsoleModel) -> None:
        self.calls.append(("read", self._held()))

    def write(self, command: Command) -> bool:
        self.calls.append(("write", self._held()))
        self.written.append(command)
        return True

    def emergency_stop(self, reason: str = "operator") -> bool:
        self.calls.append(("estop", self._held()))
        return True

    def set_stream_request(self, cameras: Sequence[CameraRequest]) -> bool:
        return True

    def heartbeat(self) -> None:
        self.calls.append(("heartbeat", self._held()))
        self.count += 1


def wait_for(condition: object, what: str) -> None:
    deadline = time.monotonic() + DEADLINE_S
    while not condition():  # type: ignore[operator]
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.001)


def test_a_guarded_call_waits_for_the_lock_and_reads_are_locked_too(
    profile: RobotProfile,
) -> None:
    lock = threading.RLock()
    model = ConsoleModel(profile)
    handle = Guarded(model, lock)
    assert unguarded(handle) is model
    # The same handle for a part of the model and the same wrapper for a method, so a
    # callback connected can be disconnected again.
    assert handle.robot is handle.robot
    assert handle.set_velocity == handle.set_velocity
    held, release, done = threading.Event(), threading.Event(), threading.Event()

    def hold() -> None:
        with lock:
            held.set()
            release.wait(DEADLINE_S)

    holder = threading.Thread(target=hold)
    holder.start()
    held.wait(DEADLINE_S)

    def call() -> None:
        handle.set_velocity("waist", 0.2)
        done.set()

    caller = threading.Thread(target=call)
    caller.start()
    assert not done.wait(0.2), "the call ran while another thread held the model's lock"
    release.set()
    assert done.wait(DEADLINE_S)
    holder.join()
    caller.join()
    assert handle.velocities()["waist"] == pytest.approx(0.2)


def test_events_hand_callbacks_to_the_thread_that_connected_them() -> None:
    # A "view" thread that takes calls (as the GUI's inbox does) connects one callback; the
    # emitting thread (this one, as the control thread) hands it over, and runs the direct one.
    posted: list[tuple[object, ...]] = []
    event: Event[[int]] = Event()
    seen: list[tuple[str, int, int]] = []
    view_thread: list[int] = []

    def connect_as_view() -> None:
        view_thread.append(threading.get_ident())
        register_dispatcher(view_thread[0], lambda fn, *args: posted.append((fn, *args)))
        event.connect(lambda n: seen.append(("view", n, threading.get_ident())))

    view = threading.Thread(target=connect_as_view)
    view.start()
    view.join()
    try:
        event.connect(lambda n: seen.append(("direct", n, threading.get_ident())), direct=True)
        event.emit(1)  # no hand-over yet: everything on the emitting thread, as before
        assert [s[:2] for s in seen] == [("view", 1), ("direct", 1)]

        class Group:
            def __init__(self) -> None:
                self.changed = event

        hand_over(Group())
        event.emit(2)
        assert seen[2] == ("direct", 2, threading.get_ident())
        assert len(seen) == 3
        assert len(posted) == 1
        fn, callback, args, kwargs = posted[0]
        fn(callback, args, kwargs)  # type: ignore[operator]
        assert seen[3][:2] == ("view", 2)
    finally:
        register_dispatcher(view_thread[0], None)


def test_a_cycle_reads_then_steps_then_writes_then_beats(profile: RobotProfile) -> None:
    clock = Clock()
    model = ConsoleModel(profile)
    lock = threading.RLock()
    beats = Beats(lock)
    manager = ControllerManager(model, lock, hardware=beats, clock=clock)
    assert beats.calls == [("write", True)]  # attached: the model's command at once
    beats.calls.clear()
    manager.cycle()
    assert beats.calls == [("read", True), ("write", True), ("heartbeat", False)]
    assert beats.count == 1
    # A changed command reaches the hardware at once, on the thread that changed it.
    beats.calls.clear()
    with lock:
        model.set_velocity("waist", 0.2)
    assert beats.calls == [("write", True)]
    assert beats.written[-1].velocity("waist") == pytest.approx(0.2)
    with lock:
        model.emergency_stop("test")
    assert ("estop", True) in beats.calls
    manager.detach()
    beats.calls.clear()
    manager.cycle()
    with lock:
        model.set_velocity("waist", 0.1)
    assert beats.calls == []


def test_a_silent_gui_with_motion_commanded_halts_the_model(profile: RobotProfile) -> None:
    clock, beats = Clock(), Beats()
    model = ConsoleModel(profile)
    manager = ControllerManager(
        model,
        threading.RLock(),
        hardware=beats,
        gui_timeout_s=0.4,
        clock=clock,
    )
    model.set_velocity("waist", 0.3)
    manager.gui_alive()
    clock.now += 0.3
    manager.cycle()
    assert model.is_moving  # silent for less than the limit
    clock.now += 0.2
    manager.cycle()
    assert not model.is_moving
    # Nothing was moving at the GUI's last sign of life: a silence halts nothing.
    manager.gui_alive()
    clock.now += 1.0
    manager.cycle()
    model.set_velocity("waist", 0.3)
    manager.gui_alive()
    clock.now += 0.1
    manager.cycle()
    assert model.is_moving


def test_a_gap_in_the_control_threads_own_cycles_halts_the_model(profile: RobotProfile) -> None:
    clock = Clock()
    model = ConsoleModel(profile)
    manager = ControllerManager(model, threading.RLock(), hardware=None, clock=clock)
    model.set_velocity("neck", 0.3)
    manager.cycle()
    clock.now += 0.01
    manager.cycle()
    assert model.is_moving
    clock.now += 0.8  # longer than the link's alive timeout: the link zeroed meanwhile
    manager.cycle()
    assert not model.is_moving


def test_the_thread_keeps_its_rate_and_counts_what_it_missed(profile: RobotProfile) -> None:
    model = ConsoleModel(profile)
    beats = Beats()
    lock = threading.RLock()
    manager = ControllerManager(model, lock, hardware=beats, rate_hz=200)
    manager.start()
    try:
        wait_for(lambda: manager.timing().cycles >= 20, "20 cycles")
        before = manager.timing()
        with lock:  # a GUI call that takes 0.1 s: the cycles wait, and it shows
            time.sleep(0.1)
        wait_for(lambda: manager.timing().cycles >= before.cycles + 5, "cycles after the wait")
        timing = manager.timing()
        assert timing.worst_period_s >= 0.1
        assert timing.overruns >= 1
        assert "control" in timing.text
        assert "overrun" in timing.text
        assert beats.count >= timing.cycles
    finally:
        manager.stop()
    assert not manager.running
    with pytest.raises(ValueError, match="control rate"):
        ControllerManager(model, lock, hardware=None, rate_hz=0.5)
