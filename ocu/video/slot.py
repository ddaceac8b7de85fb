"""One-slot mailboxes, one per camera: a producer overwrites, a consumer takes the newest.

A slow consumer therefore never builds a queue: frames it did not take in time are replaced
and counted, so memory and latency stay bounded whatever the rates on either side.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Generic, TypeVar

T = TypeVar("T")


class LatestFrames(Generic[T]):
    """A fixed number of one-item slots behind one lock; thread-safe."""

    def __init__(self, slots: int) -> None:
        if slots < 1:
            raise ValueError("need at least one slot")
        self._items: list[T | None] = [None] * slots
        self._replaced = [0] * slots
        self._put = [0] * slots
        self._closed = False
        self._cond = threading.Condition()

    @property
    def slots(self) -> int:
        """How many slots there are."""
        return len(self._items)

    def put(self, slot: int, item: T) -> bool:
        """Store item, replacing an untaken one; True when the slot was empty before.

        True is the moment to wake the consumer; while the slot stays full it already has
        a wake-up pending, so one notification per take is enough (no signal queue builds).
        """
        with self._cond:
            was_empty = self._items[slot] is None
            if not was_empty:
                self._replaced[slot] += 1
            self._items[slot] = item
            self._put[slot] += 1
            self._cond.notify_all()
            return was_empty

    def take(self, slot: int) -> T | None:
        """The newest item of a slot, emptying it; None when there is none."""
        with self._cond:
            item = self._items[slot]
            self._items[slot] = None
            return item

    def take_first(self, order: Callable[[T], float]) -> tuple[int, T] | None:
        """Take the item that comes first by `order` (e.g. the oldest), with its slot."""
        with self._cond:
            full = [
                (order(item), slot) for slot, item in enumerate(self._items) if item is not None
            ]
            if not full:
                return None
            _, slot = min(full)
            item = self._items[slot]
            self._items[slot] = None
            assert item is not None
            return slot, item

    def wait_any(self, timeout_s: float) -> bool:
        """Wait until some slot holds an item or close() is called; False on timeout."""
        with self._cond:
            return self._cond.wait_for(
                lambda: self._closed or any(item is not None for item in self._items), timeout_s
            )

    def close(self) -> None:
        """Wake every waiter for good (shutdown)."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    @property
    def closed(self) -> bool:
        """Whether close() was called."""
        with self._cond:
            return self._closed

    def replaced(self, slot: int) -> int:
        """How many items of a slot were overwritten before anyone took them."""
        with self._cond:
            return self._replaced[slot]

    def put_count(self, slot: int) -> int:
        """How many items were put into a slot."""
        with self._cond:
            return self._put[slot]
