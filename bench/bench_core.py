"""The control core under load: key press, release and Space to the datagram, the console busy.

    .venv/bin/python bench/bench_core.py [--trials 120] [--hogs 2]
    .venv/bin/python bench/bench_core.py --baseline-tree /tmp/old-main   # and against main

The simulator runs as its own process (`ocu-sim --extended`, four cameras at 640x480 and
30 fps through the protocol extension, telemetry at 10 Hz). This process is the console as an
operator runs it: the main window with every dock, offscreen at 1600x1000, the video in the
2x2 grid with the profile's correction, the 3D view redrawn 30 times a second (OSMesa), the
map dock floating beside it. Key events are *posted* to the window, so each waits in the GUI
thread's queue behind the paints, as an X event does. Measured at the wire (the link's
DatagramSent, decoded): W press -> the first RCP driving forward; W release -> the first RCP
with the drive at zero; Space while driving -> the first RCP with every axis at zero (the start
of the e-stop burst; the robot is at rest when it reads it). Each trial waits a random 5-150 ms
first, so events land at every phase of the paints. Two phases: the machine as it is, then with
`--hogs` CPU-bound processes beside the console. With `--baseline-tree DIR` the same benchmark
runs again on another checkout (`git archive main | tar -x -C DIR`) in a child process, and
the ratios are printed.

`--x11` sends real key events instead, through the X server (XTest, on a connection of the
benchmark's own), to the console shown on a private Xvfb with the xcb platform: the path an
operator's keyboard takes, including the X key reader (ocu.windows.x_keys). It runs the
benchmark twice in children, with the reader and without it (`OCU_X_KEYS=0`: Qt's key
events only), and prints the ratios; the time is taken when the event is flushed to the
server.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_console_video import WINDOW_SIZE, cpu_s, wait
from common import percentile
from key_floor import FloorProbe
from PySide6.QtCore import QCoreApplication, QEvent, QObject, QSettings, Qt, QTimer
from PySide6.QtGui import QKeyEvent
from PySide6.QtWidgets import QApplication

from ocu.core_process import CoreSpec
from ocu.gamepad.mapping import load_pad_mapping
from ocu.gamepad.virtual import VirtualPad
from ocu.link.live import UdpLink
from ocu.profile import RobotProfile, load_profile
from ocu.protocol import RemoteControlPacket
from ocu.protocol.extended import SEQUENCED_RCP_SIZE, SequencedRcp
from ocu.protocol.wire import make_codec, make_extension_codec
from ocu.records import RCP, DatagramSent, LinkEvent, LinkState
from ocu.sim.launcher import SimulatorProcess
from ocu.windows.main_window import MainWindow

if TYPE_CHECKING:
    from ocu.core.guard import LockWaits

WAIT_S = 3.0
FPS = 30
SIZE_PX = (640, 480)
HOG = "while True: pass"
SLOW_QUEUE_S = 0.010
# Left stick positions that drive forward above the servos' starting speed (bench_gamepad).
STICK_SPEEDS = (-26214, -29491, -32768)
SLOW_QUEUES: list[tuple[float, float]] = []  # (posted, dispatched) of keys that waited long


class WireProbe:
    """The first RCP leaving the link that matches what a trial waits for (the link's thread)."""

    def __init__(self, profile: RobotProfile) -> None:
        self.codec = make_codec(profile)
        # With the extension the link sends sequenced RCPs (the vendor RCP behind a number).
        self.extended = make_extension_codec(profile)
        self.axis = profile.channels["drive_linear"].axis
        self.lock = threading.Lock()
        self.want: str | None = None  # "moving", "drive zero", "all zero"
        self.since = 0.0
        self.found: float | None = None
        self.dispatched: float | None = None  # when the GUI thread took the key event

    def arm(self, want: str) -> float:
        with self.lock:
            self.want, self.found, self.dispatched = want, None, None
            self.since = time.monotonic()
            return self.since

    def rcp(self, data: bytes) -> RemoteControlPacket:
        if self.extended is not None and len(data) == SEQUENCED_RCP_SIZE:
            sequenced = self.extended.decode(data)
            assert isinstance(sequenced, SequencedRcp)
            return sequenced.rcp
        packet = self.codec.decode(data)
        assert isinstance(packet, RemoteControlPacket)
        return packet

    def on_event(self, event: LinkEvent) -> None:
        if not isinstance(event, DatagramSent) or event.kind != RCP:
            return
        with self.lock:
            if self.want is None or event.sent_at < self.since:
                return
            packet = self.rcp(event.data)
            drive = packet.axes[self.axis]
            hit = (
                (self.want == "moving" and drive != 0)
                or (self.want == "drive zero" and drive == 0)
                or (self.want == "all zero" and not any(packet.axes))
            )
            if hit:
                self.found = event.sent_at
                self.want = None


class DispatchClock(QObject):
    """Notes when the GUI thread dispatches a key event to the window (the app's filter)."""

    def __init__(self, probe: WireProbe) -> None:
        super().__init__()
        self.probe = probe

    def eventFilter(self, watched: QObject, event: QEvent) -> bool:
        if event.type() in (QEvent.Type.KeyPress, QEvent.Type.KeyRelease):
            with self.probe.lock:
                if self.probe.dispatched is None:
                    self.probe.dispatched = time.monotonic()
        return False


@dataclass
class Phase:
    """What one phase measured (ms)."""

    label: str
    press_ms: list[float] = field(default_factory=list)
    release_ms: list[float] = field(default_factory=list)
    space_ms: list[float] = field(default_factory=list)
    # The left stick (deadman held): moved to a driving speed -> the first RCP driving; back
    # to rest -> the first RCP with the drive at zero.
    stick_ms: list[float] = field(default_factory=list)
    stick_release_ms: list[float] = field(default_factory=list)
    # Of every trial: the key posted -> the GUI thread dispatching it.
    dispatch_ms: list[float] = field(default_factory=list)
    # --floor: the same X events -> a datagram from a process of their own (key_floor.py).
    floor_press_ms: list[float] = field(default_factory=list)
    floor_release_ms: list[float] = field(default_factory=list)
    floor_space_ms: list[float] = field(default_factory=list)
    cpu_percent: float = 0.0
    control: str = ""
    model_fps: float = 0.0

    def line(self, name: str, values: list[float]) -> str:
        if not values:
            return f"  {name:<16}: none"
        return (
            f"  {name:<16}: p50 {percentile(values, 50):6.2f} ms  p99 "
            f"{percentile(values, 99):7.2f} ms  max {max(values):7.2f} ms  ({len(values)})"
        )


def post_qt_key(window: MainWindow, key: Qt.Key, press: bool, text: str = "") -> None:
    kind = QEvent.Type.KeyPress if press else QEvent.Type.KeyRelease
    QCoreApplication.postEvent(window, QKeyEvent(kind, key, Qt.KeyboardModifier.NoModifier, text))


# X key codes (evdev + 8) of the keys the trials press.
X_KEYCODES = {Qt.Key.Key_W: 25, Qt.Key.Key_Space: 65}


class XTestKeys:
    """Real key events through the X server: XTest on a connection of our own ($DISPLAY)."""

    def __init__(self) -> None:
        import ctypes
        import ctypes.util

        # Called holding the GIL (PyDLL): between the time taken and the event's write to the
        # server nothing waits for this busy process's GIL (a CDLL call lets it go and takes
        # it back after each of the two calls, which put up to 5 ms of the benchmark's own
        # process into a key's figure beside the hogs).
        self.x11 = ctypes.PyDLL(ctypes.util.find_library("X11") or "libX11.so.6")
        self.xtst = ctypes.PyDLL(ctypes.util.find_library("Xtst") or "libXtst.so.6")
        self.x11.XOpenDisplay.restype = ctypes.c_void_p
        self.x11.XOpenDisplay.argtypes = [ctypes.c_char_p]
        self.x11.XFlush.argtypes = [ctypes.c_void_p]
        self.x11.XSync.argtypes = [ctypes.c_void_p, ctypes.c_int]
        self.x11.XCloseDisplay.argtypes = [ctypes.c_void_p]
        self.xtst.XTestFakeKeyEvent.argtypes = [
            ctypes.c_void_p,
            ctypes.c_uint,
            ctypes.c_int,
            ctypes.c_ulong,
        ]
        self.display = self.x11.XOpenDisplay(None)
        if not self.display:
            raise RuntimeError("no X display for XTest")

    def send(self, key: Qt.Key, press: bool) -> float:
        """Press or release `key`; the time the event left for the server (taken just before
        the two calls that write it, which hold the GIL)."""
        sent_at = time.monotonic()
        self.xtst.XTestFakeKeyEvent(self.display, X_KEYCODES[key], int(press), 0)
        self.x11.XFlush(self.display)
        return sent_at

    def close(self) -> None:
        self.x11.XCloseDisplay(self.display)


def until(
    app: QApplication, probe: WireProbe, phase: Phase, timeout_s: float = WAIT_S
) -> float | None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        app.processEvents()
        with probe.lock:
            if probe.found is not None:
                if probe.dispatched is not None:
                    phase.dispatch_ms.append(1000 * (probe.dispatched - probe.since))
                    if probe.dispatched - probe.since > SLOW_QUEUE_S:
                        SLOW_QUEUES.append((probe.since, probe.dispatched))
                return probe.found
        time.sleep(0.0005)
    return None


def run_phase(
    app: QApplication,
    window: MainWindow,
    probe: WireProbe,
    label: str,
    *,
    trials: int,
    seed: int,
    x11: XTestKeys | None = None,
    pad: VirtualPad | None = None,
    floor: FloorProbe | None = None,
) -> Phase:
    """`trials` key trials; through the X server with `x11`, else posted to Qt's queue."""

    def post_key(
        window: MainWindow, key: Qt.Key, press: bool, text: str = "", label: str = "other"
    ) -> float | None:
        """Post the key (Qt's queue) or send it (XTest); with XTest, the time it left."""
        if x11 is None:
            post_qt_key(window, key, press, text)
            return None
        sent_at = x11.send(key, press)
        if floor is not None:
            floor.expect(label, X_KEYCODES[key], press, sent_at)
        return sent_at

    phase = Phase(label)
    rng = random.Random(seed)
    renders0 = window.model_view.frames_rendered
    waits = _lock_waits()
    if waits is not None:
        waits.reset()
    connection = getattr(window.control, "connection", None)  # a core process's pipe
    trips0 = (connection.round_trips, connection.round_trip_s) if connection else (0, 0.0)
    cpu0, t0 = cpu_s(), time.monotonic()
    for trial in range(trials):
        wait(app, rng.uniform(0.005, 0.15))
        pressed = probe.arm("moving")
        pressed = post_key(window, Qt.Key.Key_W, True, "w", "press") or pressed
        at = until(app, probe, phase)
        if at is not None:
            phase.press_ms.append(1000 * (at - pressed))
        wait(app, rng.uniform(0.03, 0.12))
        if trial % 4 == 3:
            stopped = probe.arm("all zero")
            stopped = post_key(window, Qt.Key.Key_Space, True, " ", "space") or stopped
            at = until(app, probe, phase)
            if at is not None:
                phase.space_ms.append(1000 * (at - stopped))
            post_key(window, Qt.Key.Key_Space, False, " ")
            post_key(window, Qt.Key.Key_W, False, "w")
            wait(app, 0.05)
            if pad is not None:
                # After an e-stop the pad acts again only on a fresh press of its deadman.
                pad.set_button("leftshoulder", False)
                wait(app, 0.05)
                pad.set_button("leftshoulder", True)
                deadline = time.monotonic() + WAIT_S
                while not window.teleop.engaged and time.monotonic() < deadline:
                    wait(app, 0.01)
            continue
        released = probe.arm("drive zero")
        released = post_key(window, Qt.Key.Key_W, False, "w", "release") or released
        at = until(app, probe, phase)
        if at is not None:
            phase.release_ms.append(1000 * (at - released))
        if pad is not None:
            wait(app, rng.uniform(0.005, 0.15))
            moved = probe.arm("moving")
            pad.set_axis("lefty", rng.choice(STICK_SPEEDS))
            at = until(app, probe, phase)
            if at is not None:
                phase.stick_ms.append(1000 * (at - moved))
            wait(app, rng.uniform(0.03, 0.12))
            rested = probe.arm("drive zero")
            pad.set_axis("lefty", 0)
            at = until(app, probe, phase)
            if at is not None:
                phase.stick_release_ms.append(1000 * (at - rested))
    elapsed = time.monotonic() - t0
    if floor is not None:
        heard = floor.take()
        phase.floor_press_ms = heard.get("press", [])
        phase.floor_release_ms = heard.get("release", [])
        phase.floor_space_ms = heard.get("space", [])
    phase.cpu_percent = 100 * (cpu_s() - cpu0) / elapsed
    phase.model_fps = (window.model_view.frames_rendered - renders0) / elapsed
    core = getattr(window, "core", None)
    if core is not None:
        phase.control = core.timing().text
    if connection is not None:
        heavy = window.control.manager.answered(5)  # type: ignore[union-attr]
        print(f"{label}: the GUI's costliest reads: {heavy}")
        trips = connection.round_trips - trips0[0]
        spent = connection.round_trip_s - trips0[1]
        phase.control += (
            f"; GUI round trips to the core: {trips / elapsed:.0f}/s, "
            f"{1000 * spent / max(trips, 1):.2f} ms each, {100 * spent / elapsed:.1f} % of the time"
        )
    elif waits is not None:
        phase.control += (
            f"; GUI calls into the model: {waits.calls}, {waits.slow} waited > 5 ms for the "
            f"lock, the longest {1000 * waits.worst_s:.1f} ms"
        )
    return phase


def _lock_waits() -> LockWaits | None:
    """The guarded handle's lock statistics (None on a tree without the control core)."""
    try:
        from ocu.core.guard import WAITS
    except ImportError:
        return None
    return WAITS


class GuiSampler:
    """Samples the GUI thread's Python stack every millisecond (started on the GUI thread)."""

    def __init__(self, period_s: float = 0.001) -> None:
        self.ident = threading.get_ident()
        self.counts: dict[str, int] = {}
        self.samples = 0
        # Every sample (when, the stack 6 frames deep): what the GUI thread did while a key
        # waited in its queue (SLOW_QUEUES).
        self.trace: list[tuple[float, str]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(period_s,), daemon=True)
        self._thread.start()

    def _run(self, period_s: float) -> None:
        while not self._stop.wait(period_s):
            frame = sys._current_frames().get(self.ident)
            names: list[str] = []
            while frame is not None and len(names) < 6:
                code = frame.f_code
                names.append(f"{Path(code.co_filename).name}:{code.co_name}")
                frame = frame.f_back
            self.trace.append((time.monotonic(), " < ".join(names)))
            key = " < ".join(names[:3])
            self.counts[key] = self.counts.get(key, 0) + 1
            self.samples += 1

    def report(self, top: int = 25) -> None:
        self._stop.set()
        self._thread.join()
        print(f"GUI thread, {self.samples} samples (innermost Python frames):")
        for key, count in sorted(self.counts.items(), key=lambda kv: -kv[1])[:top]:
            print(f"  {100 * count / max(self.samples, 1):5.1f} %  {key}")
        print(f"while a key waited > {SLOW_QUEUE_S * 1000:.0f} ms ({len(SLOW_QUEUES)} times):")
        waiting: dict[str, int] = {}
        for since, until_at in SLOW_QUEUES:
            for at, stack in self.trace:
                if since <= at <= until_at:
                    waiting[stack] = waiting.get(stack, 0) + 1
        total = max(sum(waiting.values()), 1)
        for key, count in sorted(waiting.items(), key=lambda kv: -kv[1])[:top]:
            print(f"  {100 * count / total:5.1f} %  {key}")


PAINTS: dict[str, list[float]] = {}


def time_paints() -> None:
    """Wrap every paintEvent of the console's own widgets and pyqtgraph's view: how long each
    paint holds the GUI thread (a diagnosis: `--paint-times`)."""
    import pyqtgraph as pg

    from ocu.widgets import gamepad, map_view, model3d_surfaces, video_status, video_view

    classes: list[type] = [pg.GraphicsView]
    for module in (model3d_surfaces, video_view, map_view, video_status, gamepad):
        classes += [
            c
            for c in vars(module).values()
            if isinstance(c, type) and "paintEvent" in vars(c) and c.__module__ == module.__name__
        ]
    for cls in classes:
        original = getattr(cls, "paintEvent")  # noqa: B009 (any widget class)

        def timed(
            self: object, event: object, _original: object = original, _n: str = cls.__name__
        ) -> None:
            started = time.perf_counter()
            _original(self, event)  # type: ignore[operator]
            PAINTS.setdefault(_n, []).append(1000 * (time.perf_counter() - started))

        setattr(cls, "paintEvent", timed)  # noqa: B010


READER: dict[str, list[float]] = {}
ACT_STARTED = threading.local()  # when the reader's action began (--reader-times)


def time_reader() -> None:
    """Time the X key reader's steps (a diagnosis: `--reader-times`): the event's age when the
    reader has it (against the X server's clock, from the first event), the focus query, the
    model's lock and the action."""
    from ocu.windows import x_keys

    dispatch = x_keys.XKeyReader._dispatch
    focused = x_keys.XKeyReader._focused
    act = x_keys.RawKeys._act

    def timed_dispatch(self: x_keys.XKeyReader, display: int, event: object) -> None:
        started = time.perf_counter()
        dispatch(self, display, event)  # type: ignore[arg-type]
        READER.setdefault("dispatch (all of it)", []).append(1000 * (time.perf_counter() - started))

    def timed_focused(self: x_keys.XKeyReader, display: int) -> bool:
        started = time.perf_counter()
        result = focused(self, display)
        READER.setdefault("focus query", []).append(1000 * (time.perf_counter() - started))
        return result

    def timed_act(self: x_keys.RawKeys, name: str, pressed: bool, server_ms: int) -> bool:
        started = time.perf_counter()
        ACT_STARTED.at = started
        result = act(self, name, pressed, server_ms)
        ACT_STARTED.at = None
        READER.setdefault("act (lock, model, link)", []).append(
            1000 * (time.perf_counter() - started)
        )
        return result

    send_current = UdpLink._send_current
    send_rcp = UdpLink._send_rcp

    def timed_send_current(self: UdpLink) -> None:
        at = getattr(ACT_STARTED, "at", None)
        if at is not None:
            READER.setdefault("act: to the link's send", []).append(
                1000 * (time.perf_counter() - at)
            )
        send_current(self)

    def timed_send_rcp(self: UdpLink, packet: RemoteControlPacket) -> None:
        at = getattr(ACT_STARTED, "at", None)
        if at is not None:
            READER.setdefault("act: to the socket (send lock taken)", []).append(
                1000 * (time.perf_counter() - at)
            )
        send_rcp(self, packet)

    UdpLink._send_current = timed_send_current  # type: ignore[method-assign,assignment]
    UdpLink._send_rcp = timed_send_rcp  # type: ignore[method-assign,assignment]
    x_keys.XKeyReader._dispatch = timed_dispatch  # type: ignore[method-assign]
    x_keys.XKeyReader._focused = timed_focused  # type: ignore[method-assign]
    x_keys.RawKeys._act = timed_act  # type: ignore[method-assign]


def report_reader() -> None:
    print("X key reader steps (ms): step: count, p50, p99, max")
    for name, times in READER.items():
        print(
            f"  {name}: {len(times)}, {percentile(times, 50):.2f}, {percentile(times, 99):.2f}, "
            f"{max(times):.2f}"
        )


def report_paints() -> None:
    print("paints on the GUI thread (ms): class: count, p50, p99, max")
    for name, times in sorted(PAINTS.items(), key=lambda kv: -max(kv[1])):
        print(
            f"  {name}: {len(times)}, {percentile(times, 50):.1f}, {percentile(times, 99):.1f}, "
            f"{max(times):.1f}"
        )


def hogs(count: int) -> list[subprocess.Popen[bytes]]:
    """CPU-bound processes at the default priority (nice 0), whatever this process's is."""
    now = os.getpriority(os.PRIO_PROCESS, 0)
    prefix = ["nice", "-n", str(-now)] if now < 0 else []
    return [subprocess.Popen([*prefix, sys.executable, "-c", HOG]) for _ in range(count)]


def measure(args: argparse.Namespace) -> list[Phase]:
    app = QApplication.instance() or QApplication(sys.argv[:1])
    assert isinstance(app, QApplication)
    profile = load_profile()
    probe = WireProbe(profile)
    sim_args = ["--extended", "--telemetry-hz", "10", "--log-level", "WARNING"]
    phases = []
    with SimulatorProcess(None, sim_args) as sim, tempfile.TemporaryDirectory() as config:
        settings = QSettings(str(Path(config) / "ocu.ini"), QSettings.Format.IniFormat)

        def make_link() -> UdpLink:
            link = UdpLink(profile, sim.address, extension=True)
            link.subscribe(probe.on_event)
            return link

        extra: dict[str, object] = {"control_hz": args.control_hz} if args.control_hz else {}
        pad: Any = VirtualPad() if not args.no_pad and not args.core_process else None
        if pad is not None:
            pad.__enter__()
        if not args.no_pad:
            extra["pad_mapping"] = load_pad_mapping(profile)
        if args.core_process:
            # The core (model, control thread, link, X key reader) in a child process; the
            # probe hears the datagrams it sent through the window's RemoteLink, timed by the
            # core's own stamp (CLOCK_MONOTONIC is the machine's, not the process's).
            # The virtual pad is plugged in there: SDL's virtual pads are the process's own.
            host, port = sim.address
            parts = () if args.no_pad else ("vpad=ocu.gamepad.virtual:core_virtual_pad",)
            extra["core"] = CoreSpec(profile, "engineer", f"{host}:{port}", parts=parts)
        window = MainWindow(profile, make_link, "simulator", settings, **extra)  # type: ignore[arg-type]
        if args.core_process:
            assert window.link is not None
            window.link.link.subscribe(probe.on_event)
            if not args.no_pad:
                pad = window.control.process.part("vpad")  # type: ignore[union-attr]
        window.resize(*WINDOW_SIZE)
        window.show()
        window.activateWindow()
        dispatch_clock = DispatchClock(probe)
        app.installEventFilter(dispatch_clock)
        for camera in range(len(profile.link.camera_names)):
            window.video_panel.set_stream_request(camera, *SIZE_PX, FPS)
        deadline = time.monotonic() + 10.0
        while window.link_status.state != LinkState.CONNECTED and time.monotonic() < deadline:
            wait(app, 0.05)
        if pad is not None:
            deadline = time.monotonic() + 10.0
            while window.teleop.info is None and time.monotonic() < deadline:
                wait(app, 0.05)
            pad.set_button("leftshoulder", True)  # the deadman, held for the whole run
            while not window.teleop.engaged and time.monotonic() < deadline:
                wait(app, 0.05)
            print(f"pad engaged: {window.teleop.engaged}")
        window.video_panel.set_grid(True)
        window.map_dock.setFloating(True)
        window.map_dock.show()
        window.model_dock.show()
        window.model_dock.raise_()
        print(
            f"3D view visible: {window.model_view.isVisible()}, map: {window.map_dock.isVisible()}"
        )
        redraw = QTimer()
        redraw.setInterval(1000 // FPS)
        # A new frame of the 3D view each tick (the arm moving), not only a repaint of the
        # last one.
        redraw.timeout.connect(window.model_view.request_render)
        redraw.start()
        wait(app, args.warmup)
        x11 = XTestKeys() if args.x11 else None
        floor = FloorProbe() if x11 is not None and args.floor else None
        if x11 is not None:
            # The keyboard to the console: the X server's focus on its main window.
            window.raise_()
            window.activateWindow()
            QApplication.setActiveWindow(window)
            wait(app, 1.0)
            reader = window.key_filter.x_reader  # type: ignore[union-attr]
            where = "in the core process" if args.core_process else "in this process"
            print(f"X key reader: {reader is not None} ({where})")
        sampler = GuiSampler() if args.sample_gui else None
        phases.append(
            run_phase(
                app,
                window,
                probe,
                "idle",
                trials=args.trials,
                seed=1,
                x11=x11,
                pad=pad,
                floor=floor,
            )
        )
        procs = hogs(args.hogs)
        try:
            wait(app, 1.0)
            phases.append(
                run_phase(
                    app,
                    window,
                    probe,
                    f"{args.hogs} hogs",
                    trials=args.trials,
                    seed=2,
                    x11=x11,
                    pad=pad,
                    floor=floor,
                )
            )
        finally:
            for proc in procs:
                proc.kill()
                proc.wait()
        if x11 is not None:
            x11.close()
        if floor is not None:
            floor.close()
        redraw.stop()
        if sampler is not None:
            sampler.report()
        window.close()
        window.shutdown()
        app.processEvents()
        if pad is not None and not args.core_process:
            pad.__exit__(None, None, None)
    return phases


def report(title: str, phases: list[Phase]) -> None:
    print(title)
    for phase in phases:
        print(
            f" {phase.label}: console CPU {phase.cpu_percent:.0f} % of a core, 3D view "
            f"{phase.model_fps:.1f} frames/s{'; ' + phase.control if phase.control else ''}"
        )
        print(phase.line("W press -> RCP", phase.press_ms))
        print(phase.line("release -> zero", phase.release_ms))
        print(phase.line("Space -> zeros", phase.space_ms))
        print(phase.line("stick -> RCP", phase.stick_ms))
        print(phase.line("stick rest -> zero", phase.stick_release_ms))
        print(phase.line("(of which queued)", phase.dispatch_ms))
        if phase.floor_press_ms:
            print("  the same X events -> a datagram from a process of their own (the floor):")
            print(phase.line("  W press", phase.floor_press_ms))
            print(phase.line("  release", phase.floor_release_ms))
            print(phase.line("  Space", phase.floor_space_ms))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--trials", type=int, default=120)
    parser.add_argument("--hogs", type=int, default=2)
    parser.add_argument(
        "--nice",
        type=int,
        default=-10,
        help="the console's nice value, as `ocu` asks for by default (0: the default "
        "priority; the hogs always run at 0)",
    )
    parser.add_argument("--warmup", type=float, default=3.0)
    parser.add_argument("--control-hz", type=float, help="the control thread's rate (default)")
    parser.add_argument(
        "--baseline-nice",
        type=int,
        default=0,
        help="the baseline tree's nice value (default 0: main before ocu.priority ran at it)",
    )
    parser.add_argument(
        "--paint-times", action="store_true", help="also time every paint (a diagnosis)"
    )
    parser.add_argument(
        "--reader-times",
        action="store_true",
        help="with --x11: also time the X key reader's steps (a diagnosis)",
    )
    parser.add_argument(
        "--x11",
        action="store_true",
        help="real key events through a private Xvfb: with the X key reader and without",
    )
    parser.add_argument(
        "--floor",
        action="store_true",
        help="with --x11: also time the same X events through a process of their own "
        "(key_floor.py: what a core out of the GUI's interpreter could reach at best)",
    )
    parser.add_argument(
        "--no-pad", action="store_true", help="no virtual game controller, no stick trials"
    )
    parser.add_argument(
        "--core-process",
        action="store_true",
        help="the console with its control core in a child process (`ocu`'s default; "
        "without this flag the benchmark's console runs it in-process, as `ocu --in-process`); "
        "with --x11 against the in-process console",
    )
    parser.add_argument(
        "--x-nice",
        type=int,
        default=0,
        help="with --x11: the private X server's nice value (a diagnosis; default 0)",
    )
    parser.add_argument("--json", help="write the phases here (the baseline's child run)")
    parser.add_argument("--baseline-tree", help="another checkout to run the same benchmark on")
    parser.add_argument(
        "--sample-gui",
        action="store_true",
        help="also sample the GUI thread's Python stack every ms and print where its time goes "
        "(a diagnosis: the sampler takes the GIL too, so its latency figures are not the run's)",
    )
    args = parser.parse_args()
    # As `ocu` does first thing (ocu.priority), set here directly so that a baseline tree
    # without it runs at the same priority.
    os.setpriority(os.PRIO_PROCESS, 0, args.nice)
    print(f"console at nice {os.getpriority(os.PRIO_PROCESS, 0)}")
    print(f"{os.cpu_count()} cores; load {os.getloadavg()[0]:.1f} before the run")
    if args.x11 and os.environ.get("QT_QPA_PLATFORM") != "xcb":
        return run_x11(args)
    if args.paint_times:
        time_paints()
    if args.reader_times:
        time_reader()
    phases = measure(args)
    if args.paint_times:
        report_paints()
    if args.reader_times:
        report_reader()
    if args.json:
        Path(args.json).write_text(json.dumps([asdict(p) for p in phases]), encoding="utf-8")
        return 0
    report("this tree", phases)
    if args.baseline_tree:
        with tempfile.TemporaryDirectory() as out:
            target = Path(out) / "baseline.json"
            env = dict(os.environ, PYTHONPATH=args.baseline_tree)
            subprocess.run(
                [
                    sys.executable,
                    os.path.abspath(__file__),
                    "--trials",
                    str(args.trials),
                    "--hogs",
                    str(args.hogs),
                    "--warmup",
                    str(args.warmup),
                    "--nice",
                    str(args.baseline_nice),
                    "--json",
                    str(target),
                ],
                env=env,
                check=True,
                cwd=args.baseline_tree,
            )
            base = [Phase(**p) for p in json.loads(target.read_text(encoding="utf-8"))]
        report(f"baseline tree {args.baseline_tree}", base)
        print("p99 ratios baseline / this tree:")
        for ours, theirs in zip(phases, base, strict=True):
            ratios = []
            for name in ("press_ms", "release_ms", "space_ms", "stick_ms", "stick_release_ms"):
                a, b = getattr(ours, name), getattr(theirs, name)
                if a and b:
                    ratios.append(f"{name[:-3]} {percentile(b, 99) / percentile(a, 99):.2f}x")
            print(f"  {ours.label}: {', '.join(ratios)}")
    return 0


def run_x11(args: argparse.Namespace) -> int:
    """The --x11 parent: a private Xvfb, one child with the X key reader and one without."""
    read_fd, write_fd = os.pipe()
    # --x-nice: the X server at another priority (a diagnosis: how much of a key's tail is
    # the X server's own scheduling beside the hogs; a desktop's Xorg runs at nice 0).
    nice = ["nice", "-n", str(args.x_nice)] if args.x_nice else []
    server = subprocess.Popen(
        [
            *nice,
            *("Xvfb", "-displayfd", str(write_fd), "-screen", "0", "1920x1200x24"),
            *("-nolisten", "tcp"),
        ],
        pass_fds=(write_fd,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(write_fd)
    with os.fdopen(read_fd) as pipe:
        display = ":" + pipe.readline().strip()
    results: dict[str, list[Phase]] = {}
    try:
        with tempfile.TemporaryDirectory() as out:
            variants = [("the X key reader", "1", ""), ("Qt's key events only", "0", "")]
            if args.core_process:
                variants = [
                    ("the core process (its X key reader)", "1", "--core-process"),
                    ("the X key reader in the GUI's process", "1", ""),
                ]
            for label, switch, core in variants:
                target = Path(out) / f"{switch}{core}.json"
                env = dict(os.environ, DISPLAY=display, QT_QPA_PLATFORM="xcb", OCU_X_KEYS=switch)
                command = [sys.executable, os.path.abspath(__file__), "--x11"]
                command += [core] if core else []
                command += ["--no-pad"] if args.no_pad else []
                command += ["--trials", str(args.trials), "--hogs", str(args.hogs)]
                command += ["--warmup", str(args.warmup), "--nice", str(args.nice)]
                command += ["--reader-times"] if args.reader_times and switch == "1" else []
                command += ["--floor"] if args.floor and label == variants[0][0] else []
                subprocess.run([*command, "--json", str(target)], env=env, check=True)
                results[label] = [Phase(**p) for p in json.loads(target.read_text("utf-8"))]
    finally:
        server.terminate()
        server.wait(10)
    for label, phases in results.items():
        report(f"real X key events, {label}", phases)
    ours, theirs = results.values()
    print(f"p99 ratios {' / '.join(reversed(results))}:")
    for a_phase, b_phase in zip(ours, theirs, strict=True):
        ratios = []
        for name in ("press_ms", "release_ms", "space_ms", "stick_ms", "stick_release_ms"):
            a, b = getattr(a_phase, name), getattr(b_phase, name)
            if a and b:
                ratios.append(f"{name[:-3]} {percentile(b, 99) / percentile(a, 99):.2f}x")
        print(f"  {a_phase.label}: {', '.join(ratios)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
