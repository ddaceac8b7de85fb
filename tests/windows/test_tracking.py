"""Click-to-track in the console against the real simulator: the head camera sees a red box in
the simulated world; a click on it makes the waist and the neck centre it; Space, a motion
key and LINK LOST each end it at once (read from the datagrams the simulator received)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from PySide6.QtCore import QPoint, Qt
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.console.model import Source
from ocu.control.tracking import KP_MAX, gains_for_delay
from ocu.nav.world import parse_world
from ocu.profile import RobotProfile
from ocu.records import LinkState
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator
from ocu.windows.main_window import MainWindow
from tests.windows.console_fixtures import (
    DEADLINE_MS,
    ConsoleFactory,
    drive_axis,
    is_zero,
    wait_sim,
    wait_zeros,
)

# A red box ahead and to the left of the head camera (the arm stands at zero: the head looks
# straight ahead about 0.5 m above the floor, 0.9 m in front of the turn centre).
BOX_WORLD = {
    "box": [
        {"centre_m": [3.0, 0.55], "size_m": [0.3, 0.3], "height_m": 0.4, "colour": [230, 30, 30]}
    ],
    "start": {"xy_m": [0.0, 0.0], "heading_deg": 0.0},
}


def _head_camera(profile: RobotProfile) -> int:
    return next(
        i for i, c in enumerate(profile.cameras) if c.mount is not None and c.mount.link is not None
    )


def _sim(profile: RobotProfile, latency_ms: float) -> RobotSimulator:
    sim = RobotSimulator(
        profile,
        extended=True,
        world=parse_world(BOX_WORLD),
        telemetry_hz=20.0,
        video_fps=0.0,
        faults=FaultConfig(latency_ms=latency_ms),
        seed=5,
    )
    assert sim.extension is not None
    head = _head_camera(profile)
    for camera in range(len(profile.cameras)):
        if camera != head:
            sim.extension.stop_camera(camera)  # only the head camera costs CPU
    sim.start()
    return sim


@pytest.fixture
def box_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """The extended simulator with the red box and only the head camera streaming."""
    sim = _sim(profile, 0.0)
    yield sim
    sim.stop()


@pytest.fixture
def slow_box_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """The same, 100 ms each way on the link (200 ms round trip: the gains come down)."""
    sim = _sim(profile, 100.0)
    yield sim
    sim.stop()


def _red_centre(console: MainWindow, camera: int) -> tuple[float, float]:
    """Where the box is in the picture the console shows (normalised)."""
    frame = console.video_panel.view.current_frame(camera)
    assert frame is not None
    assert frame.decoded is not None
    pixels = frame.decoded.pixels.astype(int)
    b, g, r = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    # Without the headlight the box is a dark red.
    ys, xs = np.nonzero((r > 40) & (r > 2 * g) & (r > 2 * b))
    assert xs.size > 30, "the box is not in the head camera's picture"
    height, width = pixels.shape[:2]
    return float(xs.mean()) / width, float(ys.mean()) / height


def _click_box(console: MainWindow, qtbot: QtBot, camera: int) -> None:
    """Track mode on, then a click on the box in the head camera's picture."""
    panel = console.video_panel
    view = panel.view
    qtbot.waitUntil(lambda: view.image_rect(camera) is not None, timeout=DEADLINE_MS)
    arm = console.model.arm
    assert arm is not None
    qtbot.waitUntil(
        lambda: set(arm.controller.kinematics.joints) <= set(console.model.predicted_angles()),
        timeout=DEADLINE_MS,
    )
    panel.set_track_mode(True)
    x, y = _red_centre(console, camera)
    area = view.image_rect(camera)
    assert area is not None
    point = QPoint(area.x() + round(x * area.width()), area.y() + round(y * area.height()))
    QTest.mouseClick(view, Qt.MouseButton.LeftButton, pos=point)
    assert console.model.tracking is not None, console.video_panel.message_label.text()


def _start(console: MainWindow, qtbot: QtBot, profile: RobotProfile) -> tuple[int, str, str]:
    camera = _head_camera(profile)
    console.video_panel.select_camera(camera)
    _click_box(console, qtbot, camera)
    session = console.model.tracking_session
    assert session is not None
    pan, tilt = session.channels
    assert console.model.channel(pan).source is Source.TRACK
    assert console.model.channel(tilt).source is Source.TRACK
    return camera, pan, tilt


def test_a_click_on_the_box_centres_it_and_space_stops_everything(
    make_console: ConsoleFactory, box_sim: RobotSimulator, qtbot: QtBot, profile: RobotProfile
) -> None:
    console = make_console(box_sim, extension=True)
    camera, pan, _tilt = _start(console, qtbot, profile)
    start_error = abs(_red_centre(console, camera)[0] - 0.5)
    assert start_error > 0.1  # the box starts well left of the centre
    pan_joint = console.model.tracking_session.axes.pan_joint  # type: ignore[union-attr]
    # The box is on the left: the waist turns left (+) and the box comes to the centre.
    wait_sim(qtbot, box_sim, lambda s: s.joints_rad[pan_joint] > 0.1, "the waist turning left")

    def centred() -> bool:
        tracked = console.model.tracking
        assert tracked is not None
        box = tracked.box
        if box is None:
            return False
        return abs(box.centre[0] - 0.5) < 0.03 and abs(box.centre[1] - 0.5) < 0.05

    qtbot.waitUntil(centred, timeout=3 * DEADLINE_MS)
    # What the tracker centred is the box: its red is in the middle of the picture.
    red_x, red_y = _red_centre(console, camera)
    assert abs(red_x - 0.5) < 0.08
    assert abs(red_y - 0.5) < 0.1
    assert any(drive_axis(profile, r, pan) for r in box_sim.received_commands())
    QTest.keyPress(console, Qt.Key.Key_Space)
    assert console.model.tracking is None
    assert console.model.channel(pan).source is Source.NONE
    wait_zeros(qtbot, box_sim, "the robot stopped by the zeros")


def test_with_latency_a_motion_key_and_link_lost_end_the_tracking(
    make_console: ConsoleFactory,
    slow_box_sim: RobotSimulator,
    qtbot: QtBot,
    profile: RobotProfile,
) -> None:
    sim = slow_box_sim
    console = make_console(sim, extension=True)
    camera, pan, tilt = _start(console, qtbot, profile)
    start_error = abs(_red_centre(console, camera)[0] - 0.5)
    # 200 ms round trip: the gains are lowered, but the box still comes towards the centre.
    qtbot.waitUntil(
        lambda: abs(_red_centre(console, camera)[0] - 0.5) < start_error / 2,
        timeout=3 * DEADLINE_MS,
    )
    # The round trip was measured from the tracking's own commands; the gains follow it.
    session = console.model.tracking_session
    assert session is not None
    dead_time_s = session.dead_time_s(console.model.controller.delay_s)
    assert dead_time_s is not None
    assert dead_time_s > 0.15
    assert gains_for_delay(dead_time_s).kp < KP_MAX
    # A motion key is the operator taking over: the tracking ends, the key's command goes out.
    QTest.keyPress(console, Qt.Key.Key_E)  # hold key of the waist (right)
    assert console.model.tracking is None
    assert console.model.channel(pan).source is Source.HOTKEY
    assert console.model.channel(tilt).source is Source.NONE
    QTest.keyRelease(console, Qt.Key.Key_E)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "the robot stopped after the key")
    # Tracking again, then the link is lost: the tracking ends and nothing resumes.
    _click_box(console, qtbot, camera)
    sim.cut_link()
    qtbot.waitUntil(lambda: console.link_status.state == LinkState.LOST, timeout=DEADLINE_MS)
    assert console.model.tracking is None
    assert not console.model.is_moving
    sim.restore_link()
    qtbot.waitUntil(lambda: console.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS)
    count = len(sim.received_commands())
    qtbot.waitUntil(lambda: len(sim.received_commands()) > count + 5, timeout=DEADLINE_MS)
    assert all(is_zero(r) for r in sim.received_commands()[count:])
