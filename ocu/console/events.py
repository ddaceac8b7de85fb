"""A list of callbacks: how the console's pure models tell their views (napari's EmitterGroup)."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Generic, ParamSpec

log = logging.getLogger("ocu.console")

P = ParamSpec("P")


# Threads that take calls handed to them (the GUI thread, through ocu.qt.inbox). For the
# events of a model that runs on a control thread (`hand_over`), a callback connected on such a
# thread is called there, also when the event is emitted on the control thread.
_dispatchers: dict[int, Callable[..., None]] = {}


def register_dispatcher(thread_id: int, post: Callable[..., None] | None) -> None:
    """Callbacks connected on thread `thread_id` are handed to it with `post(fn, *args)`
    (None: no longer)."""
    if post is None:
        _dispatchers.pop(thread_id, None)
    else:
        _dispatchers[thread_id] = post


class Event(Generic[P]):
    """A list of callbacks called in order; one failing callback does not skip the others.

    Callbacks run on the emitting thread, unless the event hands over (`hand_over`, set for a
    model that a control thread runs): then a callback connected on a thread that takes calls
    (`register_dispatcher`: the GUI's) runs there - at once when emitted there, handed over
    when emitted on another thread (its errors are then logged there, not raised here).
    `direct=True` always calls on the emitting thread: what must be done before emit returns
    (a command to the link, an e-stop).
    """

    def __init__(self) -> None:
        # Each callback with the thread that connected it (None: direct).
        self._callbacks: list[tuple[Callable[P, None], int | None]] = []
        self.hands_over = False

    def connect(self, callback: Callable[P, None], *, direct: bool = False) -> None:
        """Call `callback` on every emit."""
        self._callbacks.append((callback, None if direct else threading.get_ident()))

    def disconnect(self, callback: Callable[P, None]) -> None:
        """Stop calling `callback`; no error if it was not connected."""
        for index, (connected, _owner) in enumerate(self._callbacks):
            if connected == callback:
                del self._callbacks[index]
                return

    def emit(self, *args: P.args, **kwargs: P.kwargs) -> None:
        """Call every callback; the first error is raised after all have run."""
        error: BaseException | None = None
        here = threading.get_ident() if self.hands_over else None
        for callback, owner in list(self._callbacks):
            if here is not None and owner is not None and owner != here:
                post = _dispatchers.get(owner)
                if post is not None:
                    post(_call_keywords, callback, args, kwargs)
                    continue
            try:
                callback(*args, **kwargs)
            except Exception as err:  # an e-stop must reach every subscriber
                log.exception("event callback %r failed", callback)
                error = error or err
        if error is not None:
            raise error


def hand_over(*groups: object) -> None:
    """Every Event attribute of these event groups hands callbacks over to their threads."""
    for group in groups:
        for value in vars(group).values():
            if isinstance(value, Event):
                value.hands_over = True


def _call_keywords(
    callback: Callable[..., None], args: tuple[object, ...], kwargs: dict[str, object]
) -> None:
    callback(*args, **kwargs)
