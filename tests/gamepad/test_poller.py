"""The poll thread on real SDL with a virtual pad (no Qt): hot-plug, states, taps, stalls."""

from __future__ import annotations

import threading
import time
from types import ModuleType
from typing import Any

import pytest

from ocu.gamepad import poller as poller_module
from ocu.gamepad import sdl as sdl_loader
from ocu.gamepad.pad import PadConnected, PadDisconnected, PadEvent
from ocu.gamepad.poller import THREAD_NAME, PadPoller
from ocu.gamepad.virtual import VirtualPad
from tests.gamepad.sdl_pad import JoysticksLocked, virtual_pad, wait_for

__all__ = ["virtual_pad"]


class Consumer:
    """What the Qt glue does, on the test thread."""

    def __init__(self) -> None:
        self.events: list[PadEvent] = []
        self.changed = threading.Event()
        self.poller = PadPoller(200.0, self.changed.set, self.events.append)


def down(poller: PadPoller) -> frozenset[str] | None:
    """The buttons held in the newest state."""
    state = poller.peek()
    return state.down if state is not None else None


def test_hot_plug_states_and_unplug(virtual_pad: VirtualPad) -> None:
    consumer = Consumer()
    poller = consumer.poller
    poller.start()
    try:
        assert any(t.name == THREAD_NAME for t in threading.enumerate())
        virtual_pad.attach()
        wait_for(lambda: any(isinstance(e, PadConnected) for e in consumer.events), "connected")
        connected = consumer.events[-1]
        assert isinstance(connected, PadConnected)
        assert connected.info.name == virtual_pad.name
        assert len(connected.info.guid) == 32
        first = poller.take()
        assert first is not None
        assert first.down == frozenset()
        assert poller.take() is None  # nothing new

        virtual_pad.set_axis("lefty", -20000)
        virtual_pad.set_button("leftshoulder", True)
        virtual_pad.set_axis("righttrigger", 30000)
        wait_for(lambda: (s := poller.take()) is not None and s.axis("righttrigger") > 0, "state")
        state = poller.peek()
        assert state is not None
        assert state.axis("lefty") == -20000
        assert state.down == {"leftshoulder"}

        virtual_pad.set_button("leftshoulder", False)
        virtual_pad.set_button("b", True)
        wait_for(lambda: down(poller) == frozenset({"b"}), "b down")
        taken = poller.take()
        assert taken is not None
        assert "b" in taken.pressed  # presses are handed over once
        virtual_pad.set_button("b", False)
        wait_for(lambda: down(poller) == frozenset(), "b up")
        again = poller.take()
        assert again is not None
        assert again.pressed == frozenset()

        virtual_pad.detach()
        wait_for(lambda: isinstance(consumer.events[-1], PadDisconnected), "unplugged")
        assert poller.take() is None
        virtual_pad.attach()  # plugged in again: a new instance
        wait_for(lambda: isinstance(consumer.events[-1], PadConnected), "plugged in again")
        reconnected = consumer.events[-1]
        assert isinstance(reconnected, PadConnected)
        assert reconnected.info.instance_id != connected.info.instance_id
    finally:
        poller.stop()
    assert not poller.running


def silent_s(poller: PadPoller) -> float:
    """How long ago the poll thread last finished a poll."""
    assert poller.last_poll_at is not None
    return time.monotonic() - poller.last_poll_at


def test_a_pad_announced_connected_has_its_first_state_already(virtual_pad: VirtualPad) -> None:
    """Whoever hears PadConnected can take the pad's state at once (CI once saw take() return
    None right after the event: the state was read after the announcement)."""
    taken_at_connect: list[object] = []
    states: list[int] = []

    def on_event(event: PadEvent) -> None:
        if isinstance(event, PadConnected):
            # The poll thread itself, at the moment of the announcement.
            taken_at_connect.append(poller.peek())
            taken_at_connect.append(len(states))

    poller = PadPoller(200.0, lambda: states.append(1), on_event)
    poller.start()
    try:
        virtual_pad.attach()
        wait_for(lambda: len(taken_at_connect) == 2, "connected")
        state, notified_before = taken_at_connect
        assert state is not None
        assert notified_before == 0  # no state is announced before the pad is
        wait_for(lambda: len(states) >= 1, "the first state announced after")
    finally:
        poller.stop()
        virtual_pad.detach()


def test_a_poll_thread_blocked_in_sdl_stops_reporting(virtual_pad: VirtualPad) -> None:
    consumer = Consumer()
    poller = consumer.poller
    virtual_pad.attach()
    poller.start()
    try:
        wait_for(lambda: poller.polls > 5, "polling")
        with JoysticksLocked():
            wait_for(lambda: silent_s(poller) > 0.1, "the stall seen")
        wait_for(lambda: silent_s(poller) < 0.05, "polling again")
    finally:
        poller.stop()


class CountingSdl:
    """The real `sdl2` module, with every SDL function the poll thread calls written down
    (each is a ctypes call that lets the GIL go and waits for it again when it returns)."""

    def __init__(self, sdl: ModuleType) -> None:
        self._sdl = sdl
        self.calls: list[str] = []

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._sdl, name)
        if not hasattr(attr, "argtypes"):  # not a ctypes function: a constant, a struct
            return attr

        def call(*args: Any) -> Any:
            if threading.current_thread().name == THREAD_NAME:
                self.calls.append(name)
            return attr(*args)

        return call


def test_a_stick_moved_is_published_without_reading_the_pad_back(
    virtual_pad: VirtualPad, monkeypatch: pytest.MonkeyPatch
) -> None:
    """From the wake-up that brings a stick's event to the state published, no SDL call: the
    value comes in the event. (The pad read back whole was 22 more calls, each a wait for the
    GIL behind the GUI thread's paints: stick -> datagram p99 was 14-20 ms on a busy console.)"""
    counting: list[CountingSdl] = []

    def acquire() -> Any:
        counting.append(CountingSdl(real_acquire()))
        return counting[-1]

    real_acquire = sdl_loader.acquire
    monkeypatch.setattr(sdl_loader, "acquire", acquire)
    # No whole reads in between:
    monkeypatch.setattr(poller_module, "RESYNC_S", 3600.0, raising=False)
    published: list[tuple[int, int]] = []  # (lefty, calls made until then)

    def on_state() -> None:
        state = poller.peek()
        if state is not None:
            published.append((state.axis("lefty"), len(counting[0].calls)))

    poller = PadPoller(200.0, on_state, lambda _event: None)
    poller.start()
    try:
        virtual_pad.attach()
        wait_for(lambda: poller.peek() is not None, "connected")
        for value in (-20000, 12000, -3000):
            virtual_pad.set_axis("lefty", value)

            def seen(v: int = value) -> bool:
                return any(lefty == v for lefty, _ in published)

            wait_for(seen, f"lefty {value}")
            calls = next(n for lefty, n in published if lefty == value)
            made = counting[0].calls[:calls]
            woken = len(made) - 1 - made[::-1].index("SDL_WaitEventTimeout")
            assert made[woken + 1 :] == [], made[woken + 1 :]
        assert poller.peek() is not None
        assert poller.peek().axis("lefty") == -3000  # type: ignore[union-attr]
    finally:
        poller.stop()
