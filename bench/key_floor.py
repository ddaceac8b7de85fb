"""The floor of a key's path in a process of its own: raw X key event -> a UDP datagram.

    python bench/key_floor.py HOST PORT [--cycle-ms 1.0] [--cycle-hz 50]

What a control core in a process of its own (no Qt, no GUI thread in its interpreter) could
reach at best, measured beside the real console (`bench_core.py --x11 --floor`): this process
asks the X server for XInput2 raw key events on the root window, on a connection of its own
(as ocu.windows.x_keys does), and for each one sends a datagram at once to HOST:PORT carrying
the key code, press or release, and the CLOCK_MONOTONIC time just before the send. The
benchmark pairs them with the times its XTest events left for the server.

A second thread stands in for the core's control cycle: `--cycle-ms` of Python work
(`--cycle-hz` times a second), so the reader shares its interpreter's GIL as it would with a
controller manager. No robot logic: the figure is the path's floor (the X server, the
scheduler, one wake-up of a Python thread, one send), not a core's.
"""

from __future__ import annotations

import argparse
import ctypes
import os
import select
import socket
import struct
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from ocu.windows.x_keys import (
    GENERIC_EVENT,
    XI_ALL_MASTER_DEVICES,
    XI_RAW_KEY_PRESS,
    XI_RAW_KEY_RELEASE,
    _declare,
    _library,
    _XEvent,
    _XIEventMask,
    _XIRawEvent,
)

#: key code, 1 press / 0 release, CLOCK_MONOTONIC seconds just before the send.
RECORD = struct.Struct("<iid")
READY = b"ready"


class FloorProbe:
    """The benchmark's side: starts this script, hears its datagrams and pairs each with the
    XTest event that caused it (`expect`, in the order they were sent: the server delivers
    them in that order)."""

    def __init__(self, cycle_ms: float = 1.0) -> None:
        import subprocess

        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(10.0)
        port = self.sock.getsockname()[1]
        script = os.path.abspath(__file__)
        self.proc = subprocess.Popen(
            [sys.executable, script, "127.0.0.1", str(port), "--cycle-ms", str(cycle_ms)]
        )
        data, _ = self.sock.recvfrom(64)
        if data != READY:
            raise RuntimeError(f"key_floor.py said {data!r}")
        self.sock.settimeout(None)
        self._lock = threading.Lock()
        self._heard: list[tuple[int, int, float]] = []
        self._expected: list[tuple[str, int, int, float]] = []
        threading.Thread(target=self._listen, name="floor-listen", daemon=True).start()

    def _listen(self) -> None:
        while True:
            try:
                data = self.sock.recv(64)
            except OSError:
                return
            if len(data) == RECORD.size:
                with self._lock:
                    self._heard.append(RECORD.unpack(data))

    def expect(self, label: str, code: int, pressed: bool, sent_at: float) -> None:
        """An XTest event that left for the server at `sent_at` (label: what to file it as)."""
        with self._lock:
            self._expected.append((label, code, int(pressed), sent_at))

    def take(self, settle_s: float = 1.0) -> dict[str, list[float]]:
        """The floor's latency (ms) of every expected event so far, by label; then forget."""
        deadline = time.monotonic() + settle_s
        while time.monotonic() < deadline:
            with self._lock:
                if len(self._heard) >= len(self._expected):
                    break
            time.sleep(0.01)
        with self._lock:
            expected, self._expected = self._expected, []
            heard, self._heard = self._heard, []
        out: dict[str, list[float]] = {}
        at = 0
        for label, code, pressed, sent_at in expected:
            while at < len(heard) and heard[at][:2] != (code, pressed):
                at += 1
            if at == len(heard):
                break
            out.setdefault(label, []).append(1000.0 * (heard[at][2] - sent_at))
            at += 1
        return out

    def close(self) -> None:
        self.proc.kill()
        self.proc.wait()
        self.sock.close()


def busy_cycles(cycle_s: float, period_s: float, stop: threading.Event) -> None:
    """Python work of `cycle_s` every `period_s`: the control cycle's share of the GIL."""
    while not stop.is_set():
        end = time.monotonic() + cycle_s
        total = 0
        while time.monotonic() < end:
            total += sum(range(50))
        stop.wait(max(0.0, period_s - cycle_s))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("host")
    parser.add_argument("port", type=int)
    parser.add_argument("--cycle-ms", type=float, default=1.0)
    parser.add_argument("--cycle-hz", type=float, default=50.0)
    args = parser.parse_args()
    events = _library("X11", "libX11.so.6", holding_gil=True)
    x11 = _library("X11", "libX11.so.6")
    xi = _library("Xi", "libXi.so.6")
    if events is None or x11 is None or xi is None:
        print("no libX11/libXi", file=sys.stderr)
        return 2
    _declare(x11, xi)
    _declare(events, xi)
    display = x11.XOpenDisplay(None)
    if not display:
        print("no X display", file=sys.stderr)
        return 2
    opcode, first_event, first_error = ctypes.c_int(), ctypes.c_int(), ctypes.c_int()
    x11.XQueryExtension(
        display,
        b"XInputExtension",
        ctypes.byref(opcode),
        ctypes.byref(first_event),
        ctypes.byref(first_error),
    )
    major, minor = ctypes.c_int(2), ctypes.c_int(2)
    if xi.XIQueryVersion(display, ctypes.byref(major), ctypes.byref(minor)) != 0:
        print("no XInput 2.2", file=sys.stderr)
        return 2
    mask_bytes = (ctypes.c_ubyte * 4)()
    for kind in (XI_RAW_KEY_PRESS, XI_RAW_KEY_RELEASE):
        mask_bytes[kind // 8] |= 1 << (kind % 8)
    mask = _XIEventMask(XI_ALL_MASTER_DEVICES, len(mask_bytes), mask_bytes)
    xi.XISelectEvents(display, x11.XDefaultRootWindow(display), ctypes.byref(mask), 1)
    x11.XFlush(display)
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    target = (args.host, args.port)
    stop = threading.Event()
    if args.cycle_ms > 0:
        threading.Thread(
            target=busy_cycles,
            args=(args.cycle_ms / 1000.0, 1.0 / args.cycle_hz, stop),
            daemon=True,
        ).start()
    out.sendto(READY, target)
    fd = x11.XConnectionNumber(display)
    event = _XEvent()
    try:
        while True:
            while events.XPending(display):
                events.XNextEvent(display, ctypes.byref(event))
                if event.type != GENERIC_EVENT or event.cookie.extension != opcode.value:
                    continue
                if not events.XGetEventData(display, ctypes.byref(event.cookie)):
                    continue
                try:
                    kind = event.cookie.evtype
                    if kind in (XI_RAW_KEY_PRESS, XI_RAW_KEY_RELEASE):
                        raw = ctypes.cast(event.cookie.data, ctypes.POINTER(_XIRawEvent))[0]
                        pressed = int(kind == XI_RAW_KEY_PRESS)
                        out.sendto(RECORD.pack(raw.detail, pressed, time.monotonic()), target)
                finally:
                    events.XFreeEventData(display, ctypes.byref(event.cookie))
            select.select([fd], [], [])
    except KeyboardInterrupt:
        pass
    finally:
        stop.set()
    return 0


if __name__ == "__main__":
    sys.exit(main())
