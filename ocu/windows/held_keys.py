"""Which keys are physically down now, asked of the X server (X11 only, no Qt).

The console must not act on a key it never saw go down: a key held in another window keeps
auto-repeating when the console gets the focus, and Qt reports those repeats as ordinary
presses (it cannot flag a repeat of a press it never saw). Under X11 the server knows the
truth: QueryKeymap returns the 256-bit map of the keys down, by X key code (evdev code + 8).

The query goes through libxcb with ctypes, on a connection of our own to $DISPLAY: libxcb
is what Qt's xcb platform itself runs on, so it is there whenever the console runs on X11.
Anywhere else (Wayland, Windows, macOS, offscreen, no libxcb) `XKeymapProbe.open()` returns
None and the caller falls back to what the key events themselves tell.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import weakref

from ocu import hotkeys

log = logging.getLogger("ocu.keys")

# An X key code is the evdev (Linux input) code plus this.
X_KEYCODE_OFFSET = 8
KEYMAP_BYTES = 32


class _Cookie(ctypes.Structure):
    """xcb_query_keymap_cookie_t: the request's sequence number, returned by value."""

    _fields_ = [("sequence", ctypes.c_uint)]


class _KeymapReply(ctypes.Structure):
    """xcb_query_keymap_reply_t."""

    _fields_ = [
        ("response_type", ctypes.c_uint8),
        ("pad0", ctypes.c_uint8),
        ("sequence", ctypes.c_uint16),
        ("length", ctypes.c_uint32),
        ("keys", ctypes.c_uint8 * KEYMAP_BYTES),
    ]


def _load(name: str) -> ctypes.CDLL | None:
    path = ctypes.util.find_library(name)
    candidates = [path] if path else []
    candidates.append(f"lib{name}.so.1" if name == "xcb" else f"lib{name}.so.6")
    for candidate in candidates:
        try:
            return ctypes.CDLL(candidate)
        except OSError:
            continue
    return None


def keys_in_keymap(keymap: bytes) -> frozenset[str]:
    """Key names (ocu.hotkeys positions) of the key codes set in a 32-byte X keymap."""
    names = set()
    for keycode in range(min(len(keymap), KEYMAP_BYTES) * 8):
        if keymap[keycode // 8] & (1 << (keycode % 8)):
            name = hotkeys.key_for_position(keycode - X_KEYCODE_OFFSET)
            if name is not None:
                names.add(name)
    return frozenset(names)


class XKeymapProbe:
    """A connection to the X server that answers which keys are down; GUI thread only."""

    def __init__(self, xcb: ctypes.CDLL, libc: ctypes.CDLL, connection: int) -> None:
        self._xcb = xcb
        self._libc = libc
        self._connection: int | None = connection
        # Closed when the probe is collected or at exit, whichever comes first.
        self._finalizer = weakref.finalize(self, _disconnect, xcb, connection)

    @classmethod
    def open(cls, display: str | None = None) -> XKeymapProbe | None:
        """A probe on `display` ($DISPLAY by default); None where X11 cannot be asked."""
        xcb = _load("xcb")
        libc = _load("c")
        if xcb is None or libc is None:
            return None
        try:
            xcb.xcb_connect.restype = ctypes.c_void_p
            xcb.xcb_connect.argtypes = [ctypes.c_char_p, ctypes.POINTER(ctypes.c_int)]
            xcb.xcb_connection_has_error.restype = ctypes.c_int
            xcb.xcb_connection_has_error.argtypes = [ctypes.c_void_p]
            xcb.xcb_disconnect.restype = None
            xcb.xcb_disconnect.argtypes = [ctypes.c_void_p]
            xcb.xcb_query_keymap.restype = _Cookie
            xcb.xcb_query_keymap.argtypes = [ctypes.c_void_p]
            xcb.xcb_query_keymap_reply.restype = ctypes.POINTER(_KeymapReply)
            xcb.xcb_query_keymap_reply.argtypes = [ctypes.c_void_p, _Cookie, ctypes.c_void_p]
            libc.free.restype = None
            libc.free.argtypes = [ctypes.c_void_p]
        except AttributeError:  # not the libxcb we know
            return None
        connection = xcb.xcb_connect(display.encode() if display else None, None)
        if not connection:
            return None
        if xcb.xcb_connection_has_error(connection):
            xcb.xcb_disconnect(connection)  # an errored connection must still be freed
            return None
        return cls(xcb, libc, connection)

    def pressed(self) -> frozenset[str] | None:
        """Names of the keys down now; None if the server did not answer (connection lost)."""
        connection = self._connection
        if connection is None:
            return None
        if self._xcb.xcb_connection_has_error(connection):
            self.close()
            return None
        cookie = self._xcb.xcb_query_keymap(connection)
        reply = self._xcb.xcb_query_keymap_reply(connection, cookie, None)
        if not reply:
            log.warning("X server did not answer QueryKeymap")
            return None
        try:
            keymap = bytes(reply.contents.keys)
        finally:
            self._libc.free(ctypes.cast(reply, ctypes.c_void_p))
        return keys_in_keymap(keymap)

    def close(self) -> None:
        """Drop the connection (idempotent)."""
        self._connection = None
        self._finalizer()


def _disconnect(xcb: ctypes.CDLL, connection: int) -> None:
    xcb.xcb_disconnect(connection)
