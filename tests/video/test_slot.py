"""Latest-frame mailboxes: newest wins, replaced items counted, never a queue."""

from __future__ import annotations

import threading

from ocu.video.slot import LatestFrames


def test_put_take_and_replace() -> None:
    slots: LatestFrames[str] = LatestFrames(2)
    assert slots.put(0, "a") is True  # was empty: wake the consumer
    assert slots.put(0, "b") is False  # a wake-up is already pending
    assert slots.take(0) == "b"
    assert slots.take(0) is None
    assert slots.take(1) is None
    assert (slots.replaced(0), slots.put_count(0)) == (1, 2)


def test_take_first_takes_the_oldest() -> None:
    slots: LatestFrames[float] = LatestFrames(3)
    slots.put(0, 3.0)
    slots.put(2, 1.0)
    assert slots.take_first(lambda t: t) == (2, 1.0)
    assert slots.take_first(lambda t: t) == (0, 3.0)
    assert slots.take_first(lambda t: t) is None


def test_fast_producer_slow_consumer_stays_bounded() -> None:
    slots: LatestFrames[int] = LatestFrames(1)
    wakeups = 0
    for value in range(10_000):
        wakeups += slots.put(0, value)
    assert wakeups == 1
    assert slots.take(0) == 9999
    assert slots.replaced(0) == 9999


def test_wait_any_wakes_on_put_and_on_close() -> None:
    slots: LatestFrames[int] = LatestFrames(2)
    assert not slots.wait_any(0.01)
    putter = threading.Timer(0.05, slots.put, args=(1, 5))
    putter.start()
    assert slots.wait_any(5.0)
    putter.join()
    slots.take(1)
    closer = threading.Timer(0.05, slots.close)
    closer.start()
    assert slots.wait_any(5.0)
    closer.join()
    assert slots.closed
