"""The map dock in the console: zones in the status bar, clicks set waypoints, the path mode
from a key and its end at the operator's next key, and the map in a replay."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from PySide6.QtCore import QPointF, QSettings, Qt
from PySide6.QtGui import QColor, QImage
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.link.live import UdpLink
from ocu.nav.world import load_world
from ocu.profile import RobotProfile
from ocu.record.recorder import Recorder
from ocu.record.replay_link import ReplayLink
from ocu.records import Command
from ocu.sim.simulator import RobotSimulator
from ocu.windows.main_window import MainWindow
from tests.record.helpers import Collector
from tests.windows.console_fixtures import DEADLINE_MS, ConsoleFactory, wait_sim, wait_zeros


@pytest.fixture
def room_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """An extended robot in the default room (range scans, IMU), cameras off."""
    sim = RobotSimulator(
        profile, extended=True, world=load_world("default"), telemetry_hz=10.0, video_fps=0.0
    )
    assert sim.extension is not None
    for camera in range(len(profile.link.camera_names)):
        sim.extension.stop_camera(camera)
    sim.start()
    yield sim
    sim.stop()


def test_the_map_marks_a_path_a_key_follows_it_and_any_key_ends_it(
    make_console: ConsoleFactory, room_sim: RobotSimulator, qtbot: QtBot
) -> None:
    console = make_console(room_sim, extension=True)
    status = console.nav_status
    qtbot.waitUntil(lambda: status.text() == "zones: clear", timeout=DEADLINE_MS)
    console.map_dock.raise_()
    view = console.map_panel.view
    qtbot.waitUntil(lambda: view.isVisible() and view.width() > 100, timeout=DEADLINE_MS)
    # A click 1.5 m east of the robot (the view is centred on it) marks a waypoint there.
    centre = QPointF(view.width() / 2.0, view.height() / 2.0)
    target = centre + QPointF(1.5 * view.scale_px_per_m, 0.0)
    QTest.mouseClick(view, Qt.MouseButton.LeftButton, pos=target.toPoint())
    (waypoint,) = console.model.waypoints
    assert waypoint == pytest.approx((1.5, 0.0), abs=2.0 / view.scale_px_per_m)
    # The scan is drawn: the walls' points are red on the grey map.
    image = QImage(view.size(), QImage.Format.Format_RGB32)
    view.render(image)
    reds = 0
    for x in range(0, image.width(), 2):
        for y in range(0, image.height(), 2):
            colour = QColor(image.pixel(x, y))
            reds += colour.red() > colour.green() + 40 and colour.red() > colour.blue() + 40
    assert reds > 20
    QTest.keyPress(console, Qt.Key.Key_P)
    assert console.model.assist_mode == "path"
    assert status.text().startswith("PATH MODE")
    wait_sim(qtbot, room_sim, lambda s: s.pose[0] > 0.2, "the path mode driving the robot")
    QTest.keyPress(console, Qt.Key.Key_Q)  # the waist: any operator key takes over
    QTest.keyRelease(console, Qt.Key.Key_Q)
    assert console.model.assist_mode is None
    stopped = wait_zeros(qtbot, room_sim, "the robot stopped by the zeros")
    assert stopped.collisions == 0


def test_the_map_works_in_a_replay_read_only(
    profile: RobotProfile, room_sim: RobotSimulator, tmp_path: Path, qtbot: QtBot
) -> None:
    live = Collector()
    link = UdpLink(
        profile, room_sim.address, extension=True, listener=live, gui_alive_timeout_s=None
    )
    recorder = Recorder(profile)
    recorder.attach(link)
    path = tmp_path / "drive.mcap"
    recorder.start(path)
    link.start()
    try:
        assert live.wait(lambda: len(live.telemetry) >= 5)
        link.set_command(Command(velocities={"drive_linear": 0.3}))
        assert room_sim.wait_until(lambda s: s.pose[0] > 0.5, 10.0)
        link.set_command(Command())
        assert room_sim.wait_until(lambda s: s.all_stopped, 5.0)
    finally:
        link.shutdown()
    recorder.stop()
    settings = QSettings(str(tmp_path / "ocu.ini"), QSettings.Format.IniFormat)
    source = ReplayLink(path, profile)
    window = MainWindow(profile, None, "replay", settings, replay=source)
    qtbot.addWidget(window)
    try:
        assert window.replay_controller is not None
        window.replay_controller.set_speed(4.0)
        source.play()
        nav = window.model.nav
        truth = room_sim.state().pose[0]
        qtbot.waitUntil(lambda: nav.scan()[0] is not None, timeout=DEADLINE_MS)
        # Odometry from the recorded commands and telemetry comes out where the robot went.
        qtbot.waitUntil(lambda: abs(nav.estimate().pose.x_m - truth) < 0.1, timeout=DEADLINE_MS)
        panel = window.map_panel
        assert panel.view.read_only
        assert not panel.path_button.isEnabled()
        assert not panel.override_button.isEnabled()
        assert panel.reset_button.isEnabled()
        # Click-to-track would command the joints: not in a replay.
        assert not window.video_panel.controls.track_button.isEnabled()
        panel.view.click(QPointF(10.0, 10.0))
        # A click in a replay marks nothing (the view does not forward it).
    finally:
        window.shutdown()
