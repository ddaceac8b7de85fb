"""SDL2 through pysdl2, with the library from pysdl2-dll: loaded, initialised and shut down.

SDL's subsystems are counted: the poller and a virtual pad (tests, benchmarks) each take the
game controller subsystem with `acquire()` and give it back with `release()`, under one lock
(SDL's initialisation is not thread-safe). SDL must not install its own SIGINT/SIGTERM
handlers: the console quits on those itself, sending zeros last.
"""

from __future__ import annotations

import contextlib
import ctypes
import threading
from types import ModuleType

# SDL_JoystickAttachVirtualEx (the tests' virtual pad) needs SDL 2.24.
VIRTUAL_PAD_VERSION = (2, 24, 0)

_lock = threading.Lock()


class SdlUnavailableError(RuntimeError):
    """SDL2 or pysdl2 cannot be loaded or started here."""


def load() -> ModuleType:
    """The `sdl2` module over pysdl2-dll's library (or the system's), or SdlUnavailableError."""
    # Sets PYSDL2_DLL_PATH before sdl2 loads, so sdl2 takes the wheel's library quietly.
    with contextlib.suppress(ImportError):
        import sdl2dll  # noqa: F401
    try:
        import sdl2
    except (ImportError, RuntimeError) as err:
        raise SdlUnavailableError(f"SDL2 cannot be loaded: {err}") from err
    module: ModuleType = sdl2
    return module


def version(sdl: ModuleType) -> tuple[int, int, int]:
    """The version of the SDL library loaded."""
    linked = sdl.SDL_version()
    sdl.SDL_GetVersion(ctypes.byref(linked))
    return (linked.major, linked.minor, linked.patch)


def error_text(sdl: ModuleType) -> str:
    """SDL's last error message."""
    raw = sdl.SDL_GetError()
    return raw.decode("utf-8", "replace") if isinstance(raw, bytes) else str(raw)


def acquire() -> ModuleType:
    """Start SDL's game controller subsystem (counted); SdlUnavailableError with SDL's reason."""
    sdl = load()
    with _lock:
        sdl.SDL_SetHint(sdl.SDL_HINT_NO_SIGNAL_HANDLERS, b"1")
        # Read the pad whatever window has the focus (the focus policy is the console's).
        sdl.SDL_SetHint(sdl.SDL_HINT_JOYSTICK_ALLOW_BACKGROUND_EVENTS, b"1")
        if sdl.SDL_InitSubSystem(sdl.SDL_INIT_GAMECONTROLLER) != 0:
            raise SdlUnavailableError(f"SDL game controllers cannot start: {error_text(sdl)}")
    return sdl


def release(sdl: ModuleType) -> None:
    """Give the game controller subsystem back."""
    with _lock:
        sdl.SDL_QuitSubSystem(sdl.SDL_INIT_GAMECONTROLLER)
