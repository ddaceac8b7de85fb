"""A list of callbacks: how the console's pure models tell their views (napari's EmitterGroup)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Generic, ParamSpec

log = logging.getLogger("ocu.console")

P = ParamSpec("P")


class Event(Generic[P]):
    """A list of callbacks called in order; one failing callback does not skip the others."""

    def __init__(self) -> None:
        self._callbacks: list[Callable[P, None]] = []

    def connect(self, callback: Callable[P, None]) -> None:
        """Call `callback` on every emit."""
        self._callbacks.append(callback)

    def disconnect(self, callback: Callable[P, None]) -> None:
        """Stop calling `callback`; no error if it was not connected."""
        if callback in self._callbacks:
            self._callbacks.remove(callback)

    def emit(self, *args: P.args, **kwargs: P.kwargs) -> None:
        """Call every callback; the first error is raised after all have run."""
        error: BaseException | None = None
        for callback in list(self._callbacks):
            try:
                callback(*args, **kwargs)
            except Exception as err:  # an e-stop must reach every subscriber
                log.exception("event callback %r failed", callback)
                error = error or err
        if error is not None:
            raise error
