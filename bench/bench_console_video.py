"""The whole console's cost with four cameras: CPU per thread, frames shown, paint age, keys.

    .venv/bin/python bench/bench_console_video.py                     # 640x480, 30 s
    .venv/bin/python bench/bench_console_video.py --size 1280x720 --seconds 20

The simulator runs as its own process (`ocu-sim --extended`, every camera at the given size
and 30 fps through the protocol extension). This process is the console as an operator
runs it: the main window with every dock, offscreen at 1600x1000, the video in the 2x2 grid,
each camera with the profile's correction (gray world and undistortion on every camera).
Measured after a warm-up: CPU of the process and of each thread (the GUI thread, "ocu-link",
"ocu-video", the rest) in % of one core, frames shown per second per camera, arrival-to-paint
age p50/p99 per camera, and W key press -> the RCP leaving the link (the link's DatagramSent
event, decoded) p50/p99 over the key presses made during the run (one every 150 ms).
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from common import percentile
from PySide6.QtCore import QEventLoop, QSettings, Qt, QTimer
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile, load_profile
from ocu.protocol import RemoteControlPacket
from ocu.protocol.wire import make_codec
from ocu.records import RCP, DatagramSent, LinkEvent, LinkState
from ocu.sim.launcher import SimulatorProcess
from ocu.windows.main_window import GIL_SWITCH_INTERVAL_S, MainWindow

WINDOW_SIZE = (1600, 1000)
KEY_PERIOD_MS = 150


def cpu_s() -> float:
    """User plus system CPU seconds of this process."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def thread_cpu_s() -> dict[int, float]:
    """CPU seconds of every thread of this process, by native thread id."""
    ticks = os.sysconf("SC_CLK_TCK")
    result = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/stat", encoding="ascii") as stat:
                fields = stat.read().rsplit(")", 1)[1].split()
        except OSError:
            continue  # the thread ended meanwhile
        result[int(tid)] = (int(fields[11]) + int(fields[12])) / ticks
    return result


def thread_names() -> dict[int, str]:
    """Python's name of each thread it knows, by native id; the main thread is the GUI's."""
    names = {}
    for thread in threading.enumerate():
        if thread.native_id is not None:
            names[thread.native_id] = "gui" if thread is threading.main_thread() else thread.name
    return names


def wait(app: QApplication, seconds: float) -> None:
    """Run the Qt event loop for a while."""
    loop = QEventLoop(app)
    QTimer.singleShot(round(seconds * 1000), loop.quit)
    loop.exec()


class KeyProbe:
    """Times W key presses to the first RCP with the drive axis non-zero leaving the link."""

    def __init__(self, profile: RobotProfile) -> None:
        self.codec = make_codec(profile)
        self.axis = profile.channels["drive_linear"].axis
        self.pressed_at: float | None = None
        self.latencies_ms: list[float] = []
        self.lock = threading.Lock()

    def on_event(self, event: LinkEvent) -> None:
        """A link listener (the link's threads)."""
        if not isinstance(event, DatagramSent) or event.kind != RCP:
            return
        with self.lock:
            if self.pressed_at is None:
                return
            packet = self.codec.decode(event.data)
            assert isinstance(packet, RemoteControlPacket)
            if packet.axes[self.axis] != 0:
                self.latencies_ms.append((event.sent_at - self.pressed_at) * 1000.0)
                self.pressed_at = None

    def press(self, window: MainWindow) -> None:
        """Press W (timed) and release it right after its RCP left, or at the next press."""
        QTest.keyRelease(window, Qt.Key.Key_W)
        with self.lock:
            self.pressed_at = time.monotonic()
        QTest.keyPress(window, Qt.Key.Key_W)


# Each change of the video path, cumulatively: the baseline is the console as it was.
CONFIGS: dict[str, dict[str, int | bool]] = {
    "baseline": {"fit": False, "threads": 0, "display": False},
    "+path-sized datagrams": {"fit": True, "threads": 0, "display": False},
    "+one OpenCV thread": {"fit": True, "threads": 1, "display": False},
    "+decode at the cell's size": {"fit": True, "threads": 1, "display": True},
}


def configured(profile: RobotProfile, config: dict[str, int | bool]) -> RobotProfile:
    """The profile with one configuration's video settings."""
    assert profile.extension is not None
    extension = replace(profile.extension, fit_datagrams_to_path=bool(config["fit"]))
    video = replace(
        profile.video,
        opencv_threads=int(config["threads"]),
        decode_at_display_size=bool(config["display"]),
    )
    return replace(profile, extension=extension, video=video)


@dataclass
class Result:
    """What one configuration measured."""

    label: str
    seconds: float
    cpu_percent: float
    threads_percent: dict[str, float] = field(default_factory=dict)
    fps: list[float] = field(default_factory=list)
    age_p50_ms: list[float] = field(default_factory=list)
    age_p99_ms: list[float] = field(default_factory=list)
    key_ms: list[float] = field(default_factory=list)
    model_fps: float = 0.0
    decoded_as: str = ""


def run(
    app: QApplication,
    profile: RobotProfile,
    sim_address: tuple[str, int],
    label: str,
    *,
    size_px: tuple[int, int],
    args: argparse.Namespace,
) -> Result:
    """The whole console for `args.seconds` after a warm-up, in one configuration."""
    cameras = len(profile.link.camera_names)
    probe = KeyProbe(profile)
    with tempfile.TemporaryDirectory() as config:
        settings = QSettings(str(Path(config) / "ocu.ini"), QSettings.Format.IniFormat)

        def make_link() -> UdpLink:
            link = UdpLink(profile, sim_address, extension=True)
            link.subscribe(probe.on_event)
            return link

        window = MainWindow(profile, make_link, "simulator", settings)
        window.resize(*WINDOW_SIZE)
        window.show()
        window.activateWindow()
        for camera in range(cameras):
            window.video_panel.set_stream_request(camera, *size_px, args.fps)
        deadline = time.monotonic() + 10.0
        while window.link_status.state != LinkState.CONNECTED and time.monotonic() < deadline:
            wait(app, 0.05)
        wait(app, args.warmup)
        panel = window.video_panel
        if not panel.extension_active:
            raise RuntimeError("the simulator did not answer with the extension")
        panel.set_grid(True)
        ages: dict[int, list[float]] = {camera: [] for camera in range(cameras)}

        def painted(camera: int, age_s: float) -> None:
            ages[camera].append(age_s * 1000.0)

        keys = QTimer()
        keys.setInterval(KEY_PERIOD_MS)
        keys.timeout.connect(lambda: probe.press(window))
        panel.view.frame_painted.connect(painted)
        if not args.no_keys:
            keys.start()
        renders0 = window.model_view.frames_rendered
        cpu0, threads0, t0 = cpu_s(), thread_cpu_s(), time.monotonic()
        wait(app, args.seconds)
        cpu1, threads1, t1 = cpu_s(), thread_cpu_s(), time.monotonic()
        renders = window.model_view.frames_rendered - renders0
        qt_link = window.link
        decoded_as = ""
        if qt_link is not None:
            stats = qt_link.decoder.stats(0)
            width, height = stats.last_size_px
            decoded_as = f"{width}x{height} (1/{stats.last_reduction})"
        keys.stop()
        QTest.keyRelease(window, Qt.Key.Key_W)
        panel.view.frame_painted.disconnect(painted)
        names = thread_names()
        window.close()
        window.shutdown()
        window.deleteLater()
        app.processEvents()
    elapsed = t1 - t0
    result = Result(label, elapsed, 100 * (cpu1 - cpu0) / elapsed, key_ms=probe.latencies_ms)
    result.model_fps = renders / elapsed
    result.decoded_as = decoded_as
    for tid, used in threads1.items():
        name = names.get(tid, "other (Qt, OpenCV)")
        share = 100 * (used - threads0.get(tid, 0.0)) / elapsed
        result.threads_percent[name] = result.threads_percent.get(name, 0.0) + share
    for camera in range(cameras):
        values = ages[camera] or [float("nan")]
        result.fps.append(len(ages[camera]) / elapsed)
        result.age_p50_ms.append(percentile(values, 50))
        result.age_p99_ms.append(percentile(values, 99))
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--size", default="640x480", help="stream size WxH (default 640x480)")
    parser.add_argument("--fps", type=int, default=30)
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--warmup", type=float, default=5.0)
    parser.add_argument("--no-keys", action="store_true", help="no key presses during the run")
    parser.add_argument(
        "--switch-interval-ms",
        type=float,
        default=None,
        help="sys.setswitchinterval for this run (default: what the console sets, 1 ms)",
    )
    parser.add_argument(
        "--configs",
        nargs="*",
        default=list(CONFIGS),
        help=f"which configurations, in order (default all): {', '.join(CONFIGS)}",
    )
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.lower().split("x"))
    unknown = [c for c in args.configs if c not in CONFIGS]
    if unknown:
        parser.error(f"unknown configurations {unknown}")

    app = QApplication.instance() or QApplication(sys.argv[:1])
    assert isinstance(app, QApplication)
    if args.switch_interval_ms is not None:
        sys.setswitchinterval(args.switch_interval_ms / 1000.0)
    else:
        sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)  # what each console window sets
    base = load_profile()
    sim_args = ["--extended", "--video-fps", "0", "--telemetry-hz", "10", "--log-level", "WARNING"]
    results = []
    with SimulatorProcess(None, sim_args) as sim:
        for label in args.configs:
            profile = configured(base, CONFIGS[label])
            results.append(
                run(app, profile, sim.address, label, size_px=(width, height), args=args)
            )
    names = base.link.camera_names
    print(
        f"whole console, {len(names)} cameras {width}x{height} @ {args.fps} fps over the "
        f"extension, correction as the profile says (gray world + undistortion), 2x2 grid, "
        f"{args.seconds:.0f} s per configuration, {os.cpu_count()} cores, GIL switch interval "
        f"{sys.getswitchinterval() * 1000:.1f} ms"
    )
    print(
        "| configuration | CPU % | gui | ocu-link | ocu-video | other | shown fps (each camera)"
        " | age p99 ms (worst) | key p99 ms | 3D frames/s | decoded as |"
    )
    print("|---|---:|---:|---:|---:|---:|---|---:|---:|---:|---|")
    for r in results:
        t = r.threads_percent
        known = ("gui", "ocu-link", "ocu-video")
        other = sum(v for k, v in t.items() if k not in known)
        keys = f"{percentile(r.key_ms, 99):.2f}" if r.key_ms else "—"
        print(
            f"| {r.label} | {r.cpu_percent:.0f} | {t.get('gui', 0):.0f} | "
            f"{t.get('ocu-link', 0):.0f} | {t.get('ocu-video', 0):.0f} | {other:.0f} | "
            f"{' / '.join(f'{f:.1f}' for f in r.fps)} | {max(r.age_p99_ms):.1f} | {keys} | "
            f"{r.model_fps:.1f} | {r.decoded_as} |"
        )
    first, last = results[0], results[-1]
    if len(results) > 1 and last.cpu_percent > 0:
        print(
            f"{last.label!r} uses {last.cpu_percent / first.cpu_percent:.2f}x the CPU of "
            f"{first.label!r}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
