"""What may stop a calibration that moves the robot by itself, and how it asks to go on.

A calibration moves only while the operator allows it: an e-stop (Space, the Stop button,
Ctrl-C, SIGTERM) ends it; LINK LOST ends it; releasing the deadman pauses the step (zeros)
until it is held again; an implausible reading ends it. `--yes` (a robot on a stand) holds
no deadman: `OnStand` stands in for one.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol


class CalibrationAbortedError(Exception):
    """The calibration stopped the robot and ended (e-stop, link lost, implausible reading)."""


class DeadmanReleasedError(Exception):
    """The operator let go of the deadman during a motion: the step is stopped and retried."""


class Deadman(Protocol):
    """Whether the operator holds the deadman key now (any thread)."""

    def held(self) -> bool:
        """True while motion is allowed."""
        ...


class OnStand:
    """No deadman: a robot on a stand, with nobody at the keys (`ocu calibrate --yes`)."""

    def held(self) -> bool:
        """Always allowed."""
        return True


class HeldFlag:
    """A deadman a GUI button or a test holds and releases (thread-safe)."""

    def __init__(self, held: bool = False) -> None:
        self._held = threading.Event()
        if held:
            self._held.set()

    def set(self, held: bool) -> None:
        """Hold or release."""
        if held:
            self._held.set()
        else:
            self._held.clear()

    def held(self) -> bool:
        """Whether it is held now."""
        return self._held.is_set()


class StopSignal:
    """The e-stop of a calibration: set once from any thread (or a signal handler), it stays."""

    def __init__(self) -> None:
        self._event = threading.Event()
        self.reason = ""
        self.at: float | None = None

    def stop(self, reason: str) -> None:
        """Stop the calibration now (idempotent: the first reason is kept)."""
        if not self._event.is_set():
            self.reason = reason
            self.at = time.monotonic()
            self._event.set()

    @property
    def stopped(self) -> bool:
        """Whether a stop was asked for."""
        return self._event.is_set()

    def wait(self, timeout_s: float) -> bool:
        """Wait up to timeout_s for a stop; whether one came."""
        return self._event.wait(timeout_s)
