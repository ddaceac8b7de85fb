"""A part for the core process's tests (ocu.core_process: "probe=tests.core.core_parts:probe")."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ocu.console.events import Event


class ProbeError(ValueError):
    """An error of the tests' own, raised in the core."""


class UnpicklableError(Exception):
    """An error that does not survive pickling (its constructor wants two arguments)."""

    def __init__(self, a: str, b: str) -> None:
        super().__init__(f"{a} and {b}")


class ProbeEvents:
    def __init__(self) -> None:
        self.said: Event[[int]] = Event()


class Probe:
    """What the tests ask of the core's side."""

    def __init__(self) -> None:
        self.events = ProbeEvents()
        self.value = 0

    def call_back(self, callback: Callable[..., None], *args: Any) -> None:
        callback(*args)

    def say(self, count: int) -> int:
        for number in range(count):
            self.events.said.emit(number)
        return count

    def fail(self) -> None:
        raise ProbeError("the probe failed on purpose")

    def fail_oddly(self) -> None:
        raise UnpicklableError("this", "that")

    def lock_out(self) -> object:
        import threading

        return threading.Lock()  # does not pickle


def probe(core: Any) -> Probe:
    del core
    return Probe()
