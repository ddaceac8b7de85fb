"""The Link dock on a bad radio link: its story in a picture, and its cost on the GUI thread.

    .venv/bin/python bench/bench_link_dock.py                       # cost only
    .venv/bin/python bench/bench_link_dock.py --screenshot docs/screenshots/link.png

The simulator runs as its own process (`ocu-sim --extended --loss 0.2 --latency-ms 80
--jitter-ms 40 --telemetry-hz 10`); this process is the console, offscreen at 1600x1000.
The story: the chassis turns left and right (so the robot's echoed speed commands measure
the round trip), the command rate goes from 5 to 20 Hz at 8 s, the link is cut
(`kill -USR1` to the simulator) at 18 s and restored (`kill -USR2`) at 28 s, Space at 36 s.
With --screenshot the Link dock (floated, 1100x760, 1-min window) is saved then.

The cost: the GUI thread's CPU (time.thread_time, % of one core) over --seconds with the
Link dock closed (the console without the dock: it redraws nothing) and then shown in its
place in the window, with its history filled to the 10-minute window (1200 samples); then
one update (redraw and a synchronous paint) timed 40 times: the GUI thread's CPU time
(time.thread_time, which a loaded machine does not inflate) and the wall time.
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from PySide6.QtCore import QEventLoop, QSettings, Qt, QTimer
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication

from ocu.link.live import UdpLink
from ocu.profile import load_profile
from ocu.records import LinkState
from ocu.sim.launcher import SimulatorProcess
from ocu.widgets.link_graphs import REDRAW_PERIOD_MS
from ocu.windows.main_window import MainWindow

WINDOW_SIZE = (1600, 1000)
DOCK_SIZE = (1100, 760)
SIM_ARGS = [
    "--extended",
    "--loss",
    "0.2",
    "--latency-ms",
    "80",
    "--jitter-ms",
    "40",
    "--telemetry-hz",
    "10",
    "--video-fps",
    "10",
]
TURN_PERIOD_S = 0.6
UPDATES = 40


def wait(app: QApplication, seconds: float) -> None:
    """Run the Qt event loop for a while."""
    loop = QEventLoop(app)
    QTimer.singleShot(round(seconds * 1000), loop.quit)
    loop.exec()


def wait_until(app: QApplication, condition: object, timeout_s: float, what: str) -> None:
    """Run the event loop until condition() holds; SystemExit with `what` past the deadline."""
    deadline = time.monotonic() + timeout_s
    while not condition():  # type: ignore[operator]
        if time.monotonic() > deadline:
            raise SystemExit(f"timed out waiting for {what}")
        wait(app, 0.05)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="each cost phase (10)")
    parser.add_argument("--screenshot", type=Path, help="save the Link dock's story here")
    args = parser.parse_args()
    app = QApplication.instance() or QApplication(sys.argv[:1])
    assert isinstance(app, QApplication)
    profile = load_profile()
    config = Path(tempfile.mkdtemp(prefix="ocu-bench-link-"))
    settings = QSettings(str(config / "ocu.ini"), QSettings.Format.IniFormat)
    with SimulatorProcess(None, SIM_ARGS) as simulator:
        address = simulator.address
        window = MainWindow(
            profile,
            lambda: UdpLink(profile, address, extension=True),
            f"simulator {address[0]}:{address[1]}",
            settings,
        )
        try:
            window.resize(*WINDOW_SIZE)
            window.show()
            window.activateWindow()
            wait_until(
                app,
                lambda: window.link_status.state == LinkState.CONNECTED,
                10.0,
                "the link",
            )
            panel = window.link_graphs
            if args.screenshot is not None:
                story(app, window, simulator.process.pid, args.screenshot)
            cost(app, window, args.seconds)
            del panel
        finally:
            window.shutdown()
            window.deleteLater()
    return 0


def story(app: QApplication, window: MainWindow, sim_pid: int, out: Path) -> None:
    """Turn, change the rate, cut and restore the link, stop; save the dock's picture."""
    panel = window.link_graphs
    dock = window.link_dock
    panel.window_box.setValue(1)
    dock.setFloating(True)
    dock.resize(*DOCK_SIZE)
    dock.show()
    dock.raise_()
    started = time.monotonic()
    steps = [
        (8.0, lambda: panel.rate_box.setValue(20)),
        (18.0, lambda: os.kill(sim_pid, signal.SIGUSR1)),
        (28.0, lambda: os.kill(sim_pid, signal.SIGUSR2)),
        (36.0, lambda: QTest.keyClick(window, Qt.Key.Key_Space)),
    ]
    keys = (Qt.Key.Key_A, Qt.Key.Key_D)
    turn = 0
    while time.monotonic() - started < 44.0:
        elapsed = time.monotonic() - started
        while steps and elapsed >= steps[0][0]:
            steps.pop(0)[1]()
        if 2.0 < elapsed < 34.0:
            window.activateWindow()
            QTest.keyRelease(window, keys[turn % 2])
            turn += 1
            QTest.keyPress(window, keys[turn % 2])
        wait(app, TURN_PERIOD_S)
    for key in keys:
        QTest.keyRelease(window, key)
    panel.redraw(force=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not panel.grab().save(str(out), "PNG"):
        raise SystemExit(f"cannot write {out}")
    print(f"wrote {out}; marks: {', '.join(panel.mark_labels())}")
    dock.setFloating(False)
    panel.rate_box.setValue(int(profile_rate(window)))


def profile_rate(window: MainWindow) -> float:
    """The profile's default command rate."""
    return window.profile.link.send_rate_hz


def cost(app: QApplication, window: MainWindow, seconds: float) -> None:
    """The GUI thread's CPU with the dock closed, then shown with a full 10-min history."""
    panel = window.link_graphs
    dock = window.link_dock
    dock.close()
    wait(app, 1.0)
    before = time.thread_time()
    wait(app, seconds)
    closed_percent = (time.thread_time() - before) / seconds * 100.0

    history = panel.history
    latest = history.latest()
    assert latest is not None
    now = history.clock()
    for k in range(1200):
        history.add(latest, now - 600.0 + k * 0.5)
    panel.window_box.setValue(10)
    dock.show()
    dock.raise_()
    wait(app, 1.0)
    times: list[float] = []
    seen = panel.redraws

    def collect() -> None:
        nonlocal seen
        if panel.redraws != seen:
            seen = panel.redraws
            times.append(panel.last_redraw_s * 1000.0)

    probe = QTimer()
    probe.setInterval(20)
    probe.timeout.connect(collect)
    probe.start()
    before = time.thread_time()
    wait(app, seconds)
    shown_percent = (time.thread_time() - before) / seconds * 100.0
    probe.stop()
    samples = len(history)
    print(f"GUI thread CPU, Link dock closed: {closed_percent:.1f} % of a core")
    print(
        f"GUI thread CPU, Link dock shown ({samples} samples, 10-min window): "
        f"{shown_percent:.1f} % (+{shown_percent - closed_percent:.1f})"
    )
    if times:
        print(
            f"redraws while shown: {len(times)} in {seconds:g} s, wall time p50 "
            f"{statistics.median(times):.1f} ms, max {max(times):.1f} ms (other threads hold "
            "the GIL meanwhile)"
        )
    # One update measured alone: the history read, the curves set, the plots painted.
    updates = []
    cpu = []
    for _ in range(UPDATES):
        history.add(latest, history.clock())
        started, started_cpu = time.perf_counter(), time.thread_time()
        panel.redraw(force=True)
        panel.graphics.repaint()
        updates.append((time.perf_counter() - started) * 1000.0)
        cpu.append((time.thread_time() - started_cpu) * 1000.0)
    size = f"{panel.width()}x{panel.height()} px"
    median = statistics.median(cpu)
    per_second = 1000 / REDRAW_PERIOD_MS
    print(
        f"one update (redraw + paint, {size}): GUI thread CPU p50 {median:.1f} ms, max "
        f"{max(cpu):.1f} ms (wall p50 {statistics.median(updates):.1f} ms, max "
        f"{max(updates):.1f} ms); at {per_second:g} per second: "
        f"{median * per_second / 10:.1f} % of a core"
    )


if __name__ == "__main__":
    raise SystemExit(main())
