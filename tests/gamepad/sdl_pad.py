"""Shared by the SDL tests: a virtual pad fixture, and waiting on a condition with a deadline."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import pytest

from ocu.gamepad import sdl as sdl_loader
from ocu.gamepad.virtual import VirtualPad, VirtualPadError

DEADLINE_S = 5.0


@pytest.fixture
def virtual_pad() -> Iterator[VirtualPad]:
    """A virtual pad in SDL, not yet plugged in; unplugged and released after the test."""
    pad = VirtualPad()
    try:
        pad.attach()
    except VirtualPadError as err:
        pytest.skip(f"no virtual pad here: {err}")
    pad.detach()
    yield pad
    pad.close()


def wait_for(predicate: Callable[[], bool], what: str, timeout_s: float = DEADLINE_S) -> None:
    """Wait until `predicate` holds; AssertionError naming `what` after the deadline."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"never happened: {what}")
        time.sleep(0.001)


class JoysticksLocked:
    """Hold SDL's joystick lock from this thread: the poll thread blocks inside SDL."""

    def __enter__(self) -> JoysticksLocked:
        self.sdl = sdl_loader.load()
        self.sdl.SDL_LockJoysticks()
        return self

    def __exit__(self, *_exc: object) -> None:
        self.sdl.SDL_UnlockJoysticks()
