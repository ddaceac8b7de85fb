"""The poll thread on real SDL with a virtual pad (no Qt): hot-plug, states, taps, stalls."""

from __future__ import annotations

import threading
import time

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
