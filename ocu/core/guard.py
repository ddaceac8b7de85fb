"""The GUI's handle on a model that the control thread runs: every touch under the model's lock.

The control thread (`ocu.core.manager`) holds the model's lock for each cycle; the GUI thread
calls the model's methods and reads its state through a `Guarded` handle, which takes the same
lock for each method call and each attribute read. So the model is never seen half-updated
and never updated by two threads at once, and the GUI blocks only while a cycle runs (about a
millisecond), never the other way round: the control thread never waits for the GUI.

Attributes that are themselves parts of the model (`model.robot`, `model.arm`, `model.nav` -
classes marked with `guarded = True`) are handed out guarded too; plain values (numbers,
frozen records, copies) as they are. Event groups are handed out as they are: connecting a
callback is a list append, and where the callback runs is the event's business
(`ocu.console.events.hand_over`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

# A call that waited longer than this for the lock is counted as slow.
SLOW_WAIT_S = 0.005


class LockWaits:
    """How long calls through Guarded handles waited for the model's lock (benchmarks)."""

    def __init__(self) -> None:
        self.calls = 0
        self.slow = 0
        self.worst_s = 0.0

    def reset(self) -> None:
        """Start counting afresh."""
        self.calls, self.slow, self.worst_s = 0, 0, 0.0


WAITS = LockWaits()


class Guarded:
    """`target` with every method call and attribute read under `lock`."""

    __slots__ = ("_children", "_lock", "_target", "_touched")

    def __init__(
        self,
        target: object,
        lock: threading.RLock,
        touched: Callable[[], None] | None = None,
    ) -> None:
        object.__setattr__(self, "_target", target)
        object.__setattr__(self, "_lock", lock)
        object.__setattr__(self, "_children", {})
        # Called under the lock after each method call: the caller's sign of life.
        object.__setattr__(self, "_touched", touched)

    @property
    def unguarded(self) -> Any:
        """The object itself (for the control thread, which holds the lock)."""
        return self._target

    def __getattr__(self, name: str) -> Any:
        lock = self._lock
        with lock:
            value = getattr(self._target, name)
        if getattr(type(value), "guarded", False):
            # The same handle each time, so `model.arm is model.arm` holds.
            children = self._children
            child = children.get(name)
            if child is None or child._target is not value:
                child = Guarded(value, lock, self._touched)
                children[name] = child
            return child
        if getattr(value, "__self__", None) is self._target and callable(value):
            # One wrapper per method, so a callback connected can be disconnected again.
            key = "()" + name
            cached = self._children.get(key)
            if cached is None or cached[0] != value:
                cached = (value, _locked(value, lock, self._touched))
                self._children[key] = cached
            return cached[1]
        return value

    def __setattr__(self, name: str, value: object) -> None:
        with self._lock:
            setattr(self._target, name, value)

    def __repr__(self) -> str:
        return f"Guarded({self._target!r})"


def _locked(
    method: Callable[..., Any], lock: threading.RLock, touched: Callable[[], None] | None
) -> Callable[..., Any]:
    def call(*args: Any, **kwargs: Any) -> Any:
        asked = time.perf_counter()
        with lock:
            waited = time.perf_counter() - asked
            WAITS.worst_s = max(WAITS.worst_s, waited)
            WAITS.calls += 1
            if waited > SLOW_WAIT_S:
                WAITS.slow += 1
            try:
                return method(*args, **kwargs)
            finally:
                if touched is not None:
                    touched()

    call.__name__ = getattr(method, "__name__", "call")
    call.__doc__ = method.__doc__
    return call


def unguarded(obj: object) -> Any:
    """The object behind a Guarded handle, or `obj` itself."""
    return obj.unguarded if isinstance(obj, Guarded) else obj
