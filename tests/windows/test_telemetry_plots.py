"""The telemetry plots draw by themselves: the real console and simulator, offscreen and in X.

The plots redraw on their own timer, only while on screen. Nothing here calls
`redraw(force=True)`: the curves must fill while the console simply runs, as in a window.
Once they never did: "on screen" was asked of the QGraphicsView, whose own visible region is
always empty (its viewport child covers it), on Qt's offscreen and xcb platforms alike.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PySide6.QtCore import Qt
from PySide6.QtGui import QImage
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.profile import RobotProfile
from ocu.sim.simulator import RobotSimulator
from ocu.widgets.telemetry_plots import TelemetryPlots
from ocu.windows.main_window import MainWindow
from tests.test_safety import x_env, xvfb
from tests.windows.console_fixtures import DEADLINE_MS, RUN_TIMEOUT_S, ConsoleFactory
from tests.windows.test_joint_position import type_target

__all__ = ["xvfb"]  # a fixture used below

TARGET_DEG = 40.0
MOVE_DEADLINE_MS = 20_000
# The climb spans most of the angle plot's height (about 80 px): at least this many pixels.
CLIMB_PIXELS = 30


@pytest.fixture
def sim_9_5_hz(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """The simulator at the 9.5 Hz telemetry the defect was seen with, no video."""
    simulator = RobotSimulator(profile, telemetry_hz=9.5, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


def curve_points(plots: TelemetryPlots, key: str, joint: str) -> tuple[np.ndarray, np.ndarray]:
    """What one curve holds (empty arrays before its first data)."""
    xs, ys = plots.curves[(key, joint)].getData()
    if xs is None or ys is None:
        return np.empty(0), np.empty(0)
    return np.asarray(xs), np.asarray(ys)


def pixels_painted_by(plots: TelemetryPlots, key: str, joint: str) -> int:
    """Pixels of one plot's data area that change when the joint's curve is made transparent."""
    view = plots.graphics
    curve = plots.curves[(key, joint)]
    box = view.mapFromScene(plots.plots[key].getViewBox().sceneBoundingRect()).boundingRect()

    def area() -> np.ndarray:
        image = view.viewport().grab().toImage().convertToFormat(QImage.Format.Format_RGB32)
        pixels = np.frombuffer(image.constBits(), np.uint32, image.sizeInBytes() // 4)
        rows = pixels.reshape(image.height(), image.bytesPerLine() // 4)
        return rows[box.top() : box.bottom() + 1, box.left() : box.right() + 1].copy()

    shown = area()
    curve.setOpacity(0.0)  # (hide() would also take its line out of the legend)
    try:
        without = area()
    finally:
        curve.setOpacity(1.0)
    return int(np.count_nonzero(shown != without))


def test_the_curves_fill_while_the_shoulder_moves_without_a_forced_redraw(
    make_console: ConsoleFactory, sim_9_5_hz: RobotSimulator, qtbot: QtBot
) -> None:
    console = make_console(sim_9_5_hz)
    plots = console.joint_panel.plots
    accepted = 0

    def moved_up() -> bool:
        """Up there in the simulator; a target dropped on the way is typed again.

        A loaded machine can stall the GUI thread long enough for the link to zero the motion
        commands and drop the target (that safety stop is not what this test is about).
        """
        nonlocal accepted
        if math.degrees(sim_9_5_hz.state().joints_rad["shoulder"]) >= TARGET_DEG - 1.0:
            return True
        if "shoulder" not in console.model.targets:
            type_target(console, "shoulder", f"{TARGET_DEG:g}")
            QTest.mouseClick(console.joint_panel.accept_button, Qt.MouseButton.LeftButton)
            assert "shoulder" in console.model.targets, console.joint_panel.message_label.text()
            accepted += 1
        return False

    qtbot.waitUntil(moved_up, timeout=MOVE_DEADLINE_MS)
    assert accepted >= 1

    def drawn_up_there() -> bool:
        _, angles = curve_points(plots, "position", "shoulder")
        return angles.size > 0 and float(np.nanmax(angles)) >= TARGET_DEG - 1.0

    try:
        qtbot.waitUntil(drawn_up_there, timeout=DEADLINE_MS)
    except qtbot.TimeoutError:
        history = [sample[1] for sample in console.model.robot.history["shoulder"]]
        shown = curve_points(plots, "position", "shoulder")[1].size
        raise AssertionError(f"{shown} points drawn of the shoulder's history {history}") from None
    times, angles = curve_points(plots, "position", "shoulder")
    assert float(np.min(angles)) <= 1.0  # the climb from 0° is on the curve
    assert np.all((times >= -console.model.robot.history_s) & (times <= 0.0))
    _, speeds = curve_points(plots, "speed", "shoulder")
    assert float(np.max(speeds)) > 0.1  # rad/s while it climbed
    _, currents = curve_points(plots, "current", "shoulder")
    assert currents.size > 0
    # And painted: the climb is a line of pixels in the angle and speed plots.
    for key in ("position", "speed"):
        painted = pixels_painted_by(plots, key, "shoulder")
        assert painted >= CLIMB_PIXELS, f"{key}: the shoulder's curve painted {painted} pixels"


def test_plots_behind_another_tab_wait_and_catch_up_when_raised(
    console: MainWindow, qtbot: QtBot
) -> None:
    plots = console.joint_panel.plots
    qtbot.waitUntil(lambda: drawn(plots) >= 2, timeout=DEADLINE_MS)
    assert console.arm_dock is not None  # tabbed with the joint dock in the default layout
    console.arm_dock.raise_()
    # Behind a tab the plots still count as visible to Qt, but nothing of them is on screen.
    qtbot.waitUntil(
        lambda: plots.graphics.viewport().visibleRegion().isEmpty(), timeout=DEADLINE_MS
    )
    assert plots.isVisible()
    before = drawn(plots)
    arrived = plots.sample_count("waist")
    # Several redraw periods of telemetry arrive behind the tab ...
    qtbot.waitUntil(lambda: plots.sample_count("waist") >= arrived + 8, timeout=DEADLINE_MS)
    assert drawn(plots) == before  # ... and are not drawn,
    console.joint_dock.raise_()
    qtbot.waitUntil(lambda: drawn(plots) >= arrived + 8, timeout=DEADLINE_MS)  # until raised


def drawn(plots: TelemetryPlots) -> int:
    """Samples on the waist's current curve."""
    return curve_points(plots, "current", "waist")[0].size


# ---- a real X window (Xvfb, Qt's xcb platform) ---------------------------------------------

# The console against the simulator in a child process on the X display; it reports, as one
# JSON line, what the plots drew by themselves once 20 samples had arrived (or at a deadline).
X_CONSOLE = """
import json, sys
from PySide6.QtCore import QSettings, QTimer
from PySide6.QtGui import QGuiApplication
from PySide6.QtWidgets import QApplication
from ocu.link.live import UdpLink
from ocu.profile import load_profile
from ocu.sim.simulator import RobotSimulator
from ocu.windows.main_window import MainWindow

app = QApplication([])
profile = load_profile()
sim = RobotSimulator(profile, telemetry_hz=9.5, video_fps=0.0)
sim.start()
settings = QSettings(sys.argv[1], QSettings.Format.IniFormat)
window = MainWindow(profile, lambda: UdpLink(profile, sim.address), "simulator", settings)
window.show()
plots = window.joint_panel.plots
report = {}

def check(final=False):
    samples = plots.sample_count("waist")
    drawn = {}
    for key in ("position", "speed", "current"):
        xs, _ = plots.curves[(key, "waist")].getData()
        drawn[key] = 0 if xs is None else len(xs)
    if final or (samples >= 20 and min(drawn.values()) >= 20):
        report.update(platform=QGuiApplication.platformName(), samples=samples, drawn=drawn)
        app.quit()

poll = QTimer()
poll.timeout.connect(check)
poll.start(100)
QTimer.singleShot(20_000, lambda: check(final=True))
app.exec()
window.shutdown()
sim.stop()
print(json.dumps(report))
"""


def test_the_curves_fill_in_a_real_x_window(xvfb: str, tmp_path: Path) -> None:
    env = x_env(xvfb, tmp_path)
    result = subprocess.run(
        [sys.executable, "-c", X_CONSOLE, str(tmp_path / "ocu.ini")],
        env=env,
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT_S,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert report["platform"] == "xcb"
    assert report["samples"] >= 20, report
    assert min(report["drawn"].values()) >= 20, report  # none drawn before the fix
