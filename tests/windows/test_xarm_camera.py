"""A camera of the OCU's machine in the Video dock (`ocu --camera`), on the xArm and on the
Engineer, and click-to-track on the xArm as seed 003 does it (issue 23, item 4).

Real windows (offscreen), the real xArm simulator on a pseudo-terminal, XarmLink; the camera
is the scene camera on the simulated gripper (ocu.sim.xarm_camera: the picture follows the
simulated shafts) or a video file written here, read by OpenCV as a device would be. What is
checked is what the view shows and what the SIMULATOR received.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest
from PySide6.QtCore import QSettings, Qt
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication
from pytestqt.qtbot import QtBot

from ocu.control.reach_tracking import ServoModel
from ocu.hardware.xarm import XARM_CAPABILITIES, ConsoleLinks
from ocu.hotkeys import load_key_map
from ocu.link.live import UdpLink
from ocu.profile import RobotProfile, load_profile
from ocu.profile.xarm import XarmProfile, load_xarm_profile
from ocu.profile.xarm_robot import xarm_robot_profile
from ocu.records import LinkState
from ocu.sim.simulator import RobotSimulator
from ocu.video.capture import CameraError
from ocu.widgets.video import LIVE, NO_SIGNAL
from ocu.windows.cameras import LocalCameras, SceneLinks, add_cameras
from ocu.windows.main_window import MainWindow
from tests.windows.console_fixtures import DEADLINE_MS

ROOT = Path(__file__).resolve().parents[2]
BASE = 6  # servo ID
ARM_SERVOS = {3, 4, 5, 6}


def clip(path: Path, frames: int = 20) -> Path:
    """A short video file (MJPG in AVI, 160x120, 20 fps): a red disc crossing grey."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 20.0, (160, 120))
    assert writer.isOpened()
    for index in range(frames):
        image = np.full((120, 160, 3), 128, np.uint8)
        cv2.circle(image, (20 + 6 * index, 60), 12, (40, 40, 210), -1)
        writer.write(image)
    writer.release()
    return path


@pytest.fixture
def arm() -> XarmProfile:
    return load_xarm_profile("xarm1s")


def xarm_window(
    profile: RobotProfile, links: ConsoleLinks, settings: QSettings, qtbot: QtBot
) -> MainWindow:
    window = MainWindow(
        profile,
        links.make_link,
        links.where,
        settings,
        load_key_map(profile),
        hardware_for=links.hardware_for,
        capabilities=XARM_CAPABILITIES | {"cameras"},
    )
    qtbot.addWidget(window)
    window.show()
    qtbot.waitUntil(lambda: window.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS)
    return window


@pytest.fixture
def scene_console(
    arm: XarmProfile, settings: QSettings, qtbot: QtBot
) -> Iterator[tuple[MainWindow, SceneLinks]]:
    """`ocu --profile xarm1s --camera scene`: the scene camera on the simulated gripper."""
    # The first camera rides on the gripper.
    profile = add_cameras(xarm_robot_profile(arm), ["scene"], tool_link="tool0")
    links = SceneLinks(arm, profile)
    servo = ServoModel(arm.servo.damping_ratio, arm.servo.natural_frequency_rad_s)
    cameras = LocalCameras(profile, ["scene"], scene=links, servo=servo)
    window = xarm_window(profile, links, settings, qtbot)
    cameras.attach(window)
    yield window, links
    window.shutdown()
    cameras.stop()
    links.close()
    QApplication.processEvents()


def object_point(links: SceneLinks) -> tuple[float, float]:
    """Where the scene's object is in the picture now (normalised)."""
    camera = links.scene_camera()
    seen = camera.project(camera.object_at(camera.clock()))
    assert seen is not None
    width, height = camera.calibration.size_px
    return seen[0] / width, seen[1] / height


def test_the_xarm_shows_its_gripper_camera_and_snapshots_it(
    scene_console: tuple[MainWindow, SceneLinks], qtbot: QtBot, tmp_path: Path
) -> None:
    window, links = scene_console
    panel = window.video_panel
    assert panel.camera_names == ("scene",)
    qtbot.waitUntil(lambda: panel.view.signal_state(0) == LIVE, timeout=DEADLINE_MS)
    panel.snapshot_dir = tmp_path
    path = panel.save_snapshot()
    assert path is not None
    picture = cv2.imread(str(path))
    assert picture is not None
    assert picture.shape[:2] == (480, 640)  # whole, not the size the cell shows
    hsv = cv2.cvtColor(picture, cv2.COLOR_BGR2HSV)
    red = (hsv[:, :, 1] > 120) & ((hsv[:, :, 0] < 10) | (hsv[:, :, 0] > 170))
    assert red.sum() > 5000  # the disc, where the object is seen from the gripper now
    rows, columns = np.nonzero(red)
    x, y = object_point(links)
    assert abs(columns.mean() - 640 * x) < 25
    assert abs(rows.mean() - 480 * y) < 25
    # The correction acts on it as on the robot's cameras: gray world from its next frame.
    panel.controls.colour_box.setCurrentIndex(panel.controls.colour_box.findData("gray_world"))
    link = window.link
    assert link is not None
    assert link.corrector.settings(0).colour == "gray_world"
    shown = panel.view.stats(0).shown
    qtbot.waitUntil(lambda: panel.view.stats(0).shown > shown + 3, timeout=DEADLINE_MS)
    frame = panel.view.current_frame(0)
    assert frame is not None
    assert frame.decoded is not None
    assert frame.decoded.correction.colour_ms is not None


def test_click_to_track_drives_the_arm_and_space_stops_it(
    scene_console: tuple[MainWindow, SceneLinks], qtbot: QtBot
) -> None:
    window, links = scene_console
    sim = links.simulator
    assert sim is not None
    panel = window.video_panel
    qtbot.waitUntil(lambda: panel.view.signal_state(0) == LIVE, timeout=DEADLINE_MS)
    start = sim.snapshot()
    panel.set_track_mode(True)
    assert panel.start_tracking_at(0, *object_point(links)), panel.message_label.text()
    assert window.model.tracking is not None
    # The object sways: the tracking commands the base and the pitch joints (the height and
    # the reach through the IK): the simulator receives their moves.
    qtbot.waitUntil(
        lambda: (
            {
                servo
                for _, move in sim.board.moves_since(start.time)
                for servo, _ in move.positions
                if move.duration_ms > 0
            }
            >= ARM_SERVOS
        ),
        timeout=3 * DEADLINE_MS,
    )
    qtbot.waitUntil(
        lambda: abs(sim.snapshot().setpoints[BASE] - start.setpoints[BASE]) > 2.0,
        timeout=3 * DEADLINE_MS,
    )
    window.activateWindow()
    QTest.keyClick(window, Qt.Key.Key_Space)
    qtbot.waitUntil(
        lambda: (
            (move := sim.snapshot().last_move) is not None
            and move.duration_ms == 0
            and len(move.positions) == 6
        ),
        timeout=DEADLINE_MS,
    )
    held = sim.snapshot()
    assert window.model.tracking is None
    assert window.model.estopped
    # Nothing moves the arm after Space: three more reads, and only the e-stop's repeats of
    # the stop move (every servo held where it was).
    reads = held.position_reads
    qtbot.waitUntil(lambda: sim.snapshot().position_reads >= reads + 3, timeout=DEADLINE_MS)
    assert held.last_move_at is not None
    after = [move for _, move in sim.board.moves_since(held.last_move_at)]
    assert after
    assert all(move == held.last_move for move in after)
    assert sim.snapshot().setpoints == held.targets


def test_a_file_camera_that_ends_is_shown_as_stopped(
    arm: XarmProfile, settings: QSettings, qtbot: QtBot, tmp_path: Path
) -> None:
    video = clip(tmp_path / "clip.avi")
    profile = add_cameras(xarm_robot_profile(arm), [str(video)], tool_link="tool0")
    links = ConsoleLinks(arm, profile, None)
    cameras = LocalCameras(profile, [str(video)])
    try:
        window = xarm_window(profile, links, settings, qtbot)
        cameras.attach(window)
        panel = window.video_panel
        assert panel.camera_names == ("clip",)
        qtbot.waitUntil(lambda: panel.view.stats(0).shown >= 3, timeout=DEADLINE_MS)
        # 20 frames at 20 fps: after a second it has ended, and says so; not a live picture.
        qtbot.waitUntil(lambda: panel.view.signal_state(0) == NO_SIGNAL, timeout=DEADLINE_MS)
        panel.refresh_counters()
        assert "STOPPED: end of the file" in panel.view.extra_lines[0]
        window.shutdown()
    finally:
        cameras.stop()
        links.close()
        QApplication.processEvents()


def test_the_engineer_gets_the_camera_as_one_more(
    settings: QSettings, qtbot: QtBot, tmp_path: Path
) -> None:
    base = load_profile(None)
    video = clip(tmp_path / "bench.avi", frames=200)
    profile = add_cameras(base, [str(video)])
    sim = RobotSimulator(base, telemetry_hz=10.0, video_fps=0.0)
    sim.start()
    cameras = LocalCameras(profile, [str(video)])
    window = MainWindow(
        profile, lambda: UdpLink(profile, sim.address), "simulator", settings, load_key_map(profile)
    )
    try:
        qtbot.addWidget(window)
        window.show()
        cameras.attach(window)
        panel = window.video_panel
        local = len(base.link.camera_names)
        assert panel.camera_names == (*base.link.camera_names, "bench")
        qtbot.waitUntil(
            lambda: window.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS
        )
        asked = window.model.camera
        panel.select_camera(local)  # shown, not asked of the robot
        assert window.model.camera == asked
        qtbot.waitUntil(lambda: panel.view.signal_state(local) == LIVE, timeout=DEADLINE_MS)
        # Not on the arm: tracking with it is refused, with the reason.
        assert not panel.start_tracking_at(local, 0.2, 0.5)
        assert "not on the arm" in panel.message_label.text()
    finally:
        window.shutdown()
        cameras.stop()
        sim.stop()
        QApplication.processEvents()


def test_a_camera_that_cannot_be_opened_is_named(arm: XarmProfile, tmp_path: Path) -> None:
    profile = add_cameras(xarm_robot_profile(arm), ["/dev/video99"])
    with pytest.raises(CameraError, match="/dev/video99: no such device"):
        LocalCameras(profile, ["/dev/video99"])
    not_video = tmp_path / "notes.txt"
    not_video.write_text("not a video\n")
    with pytest.raises(CameraError, match=r"notes\.txt: OpenCV cannot open it"):
        LocalCameras(add_cameras(profile, [str(not_video)]), [str(not_video)])
    result = subprocess.run(
        [sys.executable, "-m", "ocu", "--profile", "xarm1s", "--camera", "/dev/video99"],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
        check=False,
    )
    assert result.returncode == 2
    assert "camera /dev/video99: no such device or file" in result.stderr


def test_ocu_gives_a_ur_arm_the_video_dock_for_a_camera(tmp_path: Path) -> None:
    """`ocu --profile ur5e --camera FILE`: a robot without cameras gets the Video dock (it
    used to fail on the missing capability) and the camera is read."""
    video = clip(tmp_path / "desk.avi")
    result = subprocess.run(
        [sys.executable, "-m", "ocu", "--profile", "ur5e", "--camera", str(video),
         "--quit-after", "3", "--config-dir", str(tmp_path / "config"), "--no-gamepad"],
        capture_output=True,
        text=True,
        timeout=90,
        cwd=ROOT,
        check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-2000:]
    assert f"camera {video} stopped delivering: end of the file" in result.stderr
