"""A virtual game controller in SDL itself (SDL >= 2.24): the console sees it as a real pad.

The tests and the benchmark drive the console through it: `SDL_JoystickAttachVirtualEx`
adds a joystick that SDL's game controller layer maps like an Xbox pad, and setting its
axes and buttons is what a person does with a real one. It can be unplugged (`detach`) while
a stick is held.
"""

from __future__ import annotations

import ctypes
from types import ModuleType
from typing import Any

from ocu.gamepad import sdl as sdl_loader
from ocu.gamepad.pad import AXES, BUTTONS, RAW_MAX, RAW_MIN, TRIGGERS

# An Xbox 360 pad's USB ids: SDL reports the pad as one.
XBOX360_VENDOR = 0x045E
XBOX360_PRODUCT = 0x028E


class VirtualPadError(RuntimeError):
    """The virtual pad cannot be made here (SDL missing or older than 2.24)."""


class VirtualPad:
    """A virtual Xbox-like pad; `attach()` plugs it in, `detach()` unplugs it."""

    def __init__(self, name: str = "ocu virtual pad") -> None:
        self.name = name
        self._sdl: ModuleType | None = None
        self._index: int | None = None
        self._joystick: Any = None

    def __enter__(self) -> VirtualPad:
        self.attach()
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    @property
    def attached(self) -> bool:
        """Whether it is plugged in."""
        return self._joystick is not None

    def attach(self) -> None:
        """Plug the pad in (at rest: sticks centred, triggers and buttons released)."""
        if self._sdl is None:
            try:
                self._sdl = sdl_loader.acquire()
            except sdl_loader.SdlUnavailableError as err:
                raise VirtualPadError(str(err)) from err
            if sdl_loader.version(self._sdl) < sdl_loader.VIRTUAL_PAD_VERSION:
                self.close()
                raise VirtualPadError("SDL >= 2.24 is needed for a virtual pad")
        sdl = self._sdl
        if self._joystick is not None:
            return
        desc = sdl.SDL_VirtualJoystickDesc()
        desc.version = sdl.SDL_VIRTUAL_JOYSTICK_DESC_VERSION
        desc.type = sdl.SDL_JOYSTICK_TYPE_GAMECONTROLLER
        desc.naxes = len(AXES)
        desc.nbuttons = len(BUTTONS)
        desc.nhats = 0
        desc.vendor_id = XBOX360_VENDOR
        desc.product_id = XBOX360_PRODUCT
        desc.name = self.name.encode()
        index = sdl.SDL_JoystickAttachVirtualEx(ctypes.byref(desc))
        if index < 0:
            raise VirtualPadError(f"cannot attach a virtual pad: {sdl_loader.error_text(sdl)}")
        joystick = sdl.SDL_JoystickOpen(index)
        if not joystick:
            raise VirtualPadError(f"cannot open the virtual pad: {sdl_loader.error_text(sdl)}")
        self._index, self._joystick = index, joystick

    def detach(self) -> None:
        """Unplug the pad, whatever is held."""
        sdl, joystick = self._sdl, self._joystick
        if sdl is None or joystick is None:
            return
        instance = sdl.SDL_JoystickInstanceID(joystick)
        sdl.SDL_JoystickClose(joystick)
        self._joystick = None
        # The device index may have moved since attach: find it by its instance id.
        for index in range(sdl.SDL_NumJoysticks()):
            if sdl.SDL_JoystickGetDeviceInstanceID(index) == instance:
                sdl.SDL_JoystickDetachVirtual(index)
                break
        self._index = None

    def close(self) -> None:
        """Unplug and give SDL back; idempotent."""
        self.detach()
        if self._sdl is not None:
            sdl_loader.release(self._sdl)
            self._sdl = None

    def set_axis(self, axis: str, value: int) -> None:
        """Move a stick (-32768..32767) or a trigger (0..32767) to what the console will read."""
        sdl = self._need()
        low = 0 if axis in TRIGGERS else RAW_MIN
        if not low <= value <= RAW_MAX:
            raise ValueError(f"{axis}: value {value} outside {low}..{RAW_MAX}")
        raw = value
        if axis in TRIGGERS:
            # SDL maps the virtual trigger's full joystick range onto 0..32767.
            raw = round(value * (RAW_MAX - RAW_MIN) / RAW_MAX) + RAW_MIN
        if sdl.SDL_JoystickSetVirtualAxis(self._joystick, AXES.index(axis), raw) != 0:
            raise VirtualPadError(f"set {axis}: {sdl_loader.error_text(sdl)}")

    def set_button(self, button: str, down: bool) -> None:
        """Press or release a button."""
        sdl = self._need()
        state = 1 if down else 0
        if sdl.SDL_JoystickSetVirtualButton(self._joystick, BUTTONS.index(button), state) != 0:
            raise VirtualPadError(f"set {button}: {sdl_loader.error_text(sdl)}")

    def release_all(self) -> None:
        """Every stick centred, trigger and button released."""
        for axis in AXES:
            self.set_axis(axis, 0)
        for button in BUTTONS:
            self.set_button(button, False)

    def _need(self) -> ModuleType:
        if self._sdl is None or self._joystick is None:
            raise VirtualPadError("the virtual pad is not attached")
        return self._sdl


def core_virtual_pad(core: Any) -> VirtualPad:
    """A virtual pad plugged into a control core's process (ocu.core_process), as the part
    "vpad" before its "pad": tests and benchmarks move its sticks through the core's pipe,
    where the core's own poller reads them (SDL's virtual pads are the process's own)."""
    del core
    pad = VirtualPad()
    pad.attach()
    return pad
