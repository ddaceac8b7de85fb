"""The 3D widget under pytest-qt (offscreen Qt, so the OSMesa path): state, mouse, telemetry."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass

import numpy as np
import pytest
from PySide6.QtCore import QPoint, QPointF, Qt
from PySide6.QtGui import QMouseEvent, QWheelEvent
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication, QWidget
from pytestqt.qtbot import QtBot

from ocu.profile import RobotProfile
from ocu.protocol import MotorRecord, TelemetryPacket
from ocu.protocol.mapping import rad_to_ticks, read_telemetry
from ocu.records import Command, JointReading
from ocu.render.platform import offscreen_gl_mode
from ocu.widgets.model3d import Model3DWidget, image_array

DEADLINE_MS = 5000


@dataclass(frozen=True)
class Frame:
    """The two fields of a link telemetry frame that the widget reads."""

    readings: Mapping[str, JointReading]
    received_at: float


@pytest.fixture
def widget(qtbot: QtBot, profile: RobotProfile) -> Iterator[Model3DWidget]:
    view = Model3DWidget(profile)
    qtbot.addWidget(view)
    view.resize(320, 240)
    view.show()
    qtbot.waitUntil(lambda: view.frames_rendered >= 1, timeout=DEADLINE_MS)
    yield view
    view.release()


def _amber_pixels(view: Model3DWidget) -> int:
    view.render_now()
    rgb = image_array(view.grab().toImage())[:, :, :3].astype(np.int64)
    r, g, b = rgb[:, :, 0], rgb[:, :, 1], rgb[:, :, 2]
    return int(((r > 170) & (g > 80) & (g < 170) & (b < 70)).sum())


def _all_joints(profile: RobotProfile, value: float = 0.2) -> dict[str, float]:
    return {m.name: value for m in profile.motors.values() if m.has_position}


def test_offscreen_widget_draws_the_robot_offscreen(widget: Model3DWidget) -> None:
    assert widget.gl_mode == offscreen_gl_mode()
    assert widget.render_error is None
    image = image_array(widget.grab().toImage())
    assert image.shape[:2] == (240, 320)
    colours = {tuple(c) for c in image[:, :, :3].reshape(-1, 3)[::5].tolist()}
    assert len(colours) > 30


def test_joint_updates_change_matrices_not_buffers(qtbot: QtBot, widget: Model3DWidget) -> None:
    uploads = widget.buffer_uploads
    assert uploads > 0
    before = image_array(widget.grab().toImage())
    for step in range(30):
        frames = widget.frames_rendered
        with qtbot.waitSignal(widget.frame_rendered, timeout=DEADLINE_MS):
            widget.set_joint_angles({"shoulder": 0.05 * step, "elbow": -0.04 * step})
        assert widget.frames_rendered == frames + 1
    assert widget.live.position("shoulder") == pytest.approx(0.05 * 29)
    assert widget.buffer_uploads == uploads
    assert (image_array(widget.grab().toImage()) != before).any()


def test_bursts_of_updates_are_rate_limited(qtbot: QtBot, widget: Model3DWidget) -> None:
    with qtbot.waitSignal(widget.frame_rendered, timeout=DEADLINE_MS):
        widget.set_joint_angles({"waist": 0.0001})
    frames = widget.frames_rendered
    with qtbot.waitSignal(widget.frame_rendered, timeout=DEADLINE_MS):
        for step in range(200):
            widget.set_joint_angles({"waist": 0.001 * step})
    assert widget.frames_rendered - frames <= 2
    assert widget.live.position("waist") == pytest.approx(0.199)


def test_unknown_names_and_bad_values_are_ignored(widget: Model3DWidget) -> None:
    widget.set_joint_angles({"left_track": 1.0, "knee": 2.0, "elbow": math.nan, "neck": 0.3})
    assert widget.live.position("neck") == 0.3
    assert widget.live.position("elbow") == 0.0


def test_joints_without_fresh_telemetry_turn_amber(qtbot: QtBot, profile: RobotProfile) -> None:
    view = Model3DWidget(profile, stale_after_s=0.6)
    qtbot.addWidget(view)
    view.resize(320, 240)
    view.show()
    assert view.stale_joints() == view.tracked_joints  # nothing heard yet
    assert _amber_pixels(view) > 200
    view.set_joint_angles(_all_joints(profile))
    assert view.stale_joints() == frozenset()
    assert view.drawn_stale_joints == frozenset()
    assert _amber_pixels(view) == 0
    # No more telemetry: the freshness timer notices and redraws in amber.
    qtbot.waitUntil(lambda: "shoulder" in view.drawn_stale_joints, timeout=DEADLINE_MS)
    assert view.drawn_stale_joints == view.tracked_joints
    assert _amber_pixels(view) > 200
    view.set_joint_angles(_all_joints(profile), fresh_at=time.monotonic() - 10.0)
    assert view.stale_joints() == view.tracked_joints  # old news stays stale
    view.set_joint_angles(_all_joints(profile))
    view.mark_stale({"elbow"})
    assert view.stale_joints() == {"elbow"}
    view.set_joint_angles({"elbow": 0.1})
    assert view.stale_joints() == frozenset()
    view.release()


def test_ghost_shows_targets_and_follows_the_other_joints(widget: Model3DWidget) -> None:
    assert widget.build_frame(320, 240).ghosts == []
    widget.set_ghost({"shoulder": 1.2, "knee": 3.0})
    assert widget.ghost_targets == {"shoulder": 1.2}
    ghosts = {item.link for item in widget.build_frame(320, 240).ghosts}
    assert {"upper_arm", "forearm", "head"} <= ghosts
    assert "base_link" not in ghosts
    assert "turret" not in ghosts
    widget.set_joint_angles({"waist": 0.7})
    assert widget.ghost is not None
    assert widget.ghost.position("waist") == 0.7
    assert widget.ghost.position("shoulder") == 1.2
    widget.set_ghost(None)
    assert widget.ghost is None
    assert widget.build_frame(320, 240).ghosts == []


def _send_mouse(
    view: Model3DWidget,
    kind: QMouseEvent.Type,
    pos: tuple[int, int],
    button: Qt.MouseButton,
    buttons: Qt.MouseButton,
    *,
    modifiers: Qt.KeyboardModifier = Qt.KeyboardModifier.NoModifier,
) -> None:
    local = QPointF(*pos)
    event = QMouseEvent(kind, local, view.mapToGlobal(local), button, buttons, modifiers)
    QApplication.sendEvent(view, event)


def _drag(
    view: Model3DWidget,
    button: Qt.MouseButton,
    delta: tuple[int, int],
    modifiers: Qt.KeyboardModifier = Qt.KeyboardModifier.NoModifier,
) -> None:
    start = (160, 120)
    end = (160 + delta[0], 120 + delta[1])
    press, move, release = (
        QMouseEvent.Type.MouseButtonPress,
        QMouseEvent.Type.MouseMove,
        QMouseEvent.Type.MouseButtonRelease,
    )
    _send_mouse(view, press, start, button, button, modifiers=modifiers)
    _send_mouse(view, move, end, Qt.MouseButton.NoButton, button, modifiers=modifiers)
    _send_mouse(view, release, end, button, Qt.MouseButton.NoButton, modifiers=modifiers)


def test_mouse_orbits_pans_zooms_and_resets(qtbot: QtBot, widget: Model3DWidget) -> None:
    camera = widget.camera
    surfaces = [c for c in widget.findChildren(QWidget) if hasattr(c, "request_render")]
    assert len(surfaces) == 1  # the picture; the mouse goes through it to the widget
    assert surfaces[0].testAttribute(Qt.WidgetAttribute.WA_TransparentForMouseEvents)
    azimuth, elevation = camera.azimuth_deg, camera.elevation_deg
    _drag(widget, Qt.MouseButton.LeftButton, (50, 20))
    assert camera.azimuth_deg == pytest.approx(azimuth - 20.0)
    assert camera.elevation_deg == pytest.approx(elevation + 8.0)
    target = camera.target.copy()
    _drag(widget, Qt.MouseButton.MiddleButton, (30, 0))
    assert not np.allclose(camera.target, target)
    target = camera.target.copy()
    _drag(widget, Qt.MouseButton.LeftButton, (0, 30), Qt.KeyboardModifier.ShiftModifier)
    assert not np.allclose(camera.target, target)
    assert camera.azimuth_deg == pytest.approx(azimuth - 20.0)  # panned, not orbited
    distance = camera.distance
    wheel = QWheelEvent(
        QPointF(160, 120), widget.mapToGlobal(QPointF(160, 120)), QPoint(0, 0),
        QPoint(0, 240), Qt.MouseButton.NoButton, Qt.KeyboardModifier.NoModifier,
        Qt.ScrollPhase.NoScrollPhase, False,
    )  # fmt: skip
    QApplication.sendEvent(widget, wheel)
    assert camera.distance == pytest.approx(distance * 0.85**2)
    frames = widget.frames_rendered
    QTest.mouseDClick(widget, Qt.MouseButton.LeftButton, pos=QPoint(160, 120))
    assert (camera.azimuth_deg, camera.elevation_deg) == (-50.0, 24.0)
    qtbot.waitUntil(lambda: widget.frames_rendered > frames, timeout=DEADLINE_MS)


def test_preset_views_by_api_and_keys(qtbot: QtBot, widget: Model3DWidget) -> None:
    widget.set_view("top")
    assert widget.camera.elevation_deg == 90.0
    widget.setFocus()
    QTest.keyClick(widget, Qt.Key.Key_1)
    assert (widget.camera.azimuth_deg, widget.camera.elevation_deg) == (0.0, 0.0)
    QTest.keyClick(widget, Qt.Key.Key_2)
    assert widget.camera.azimuth_deg == -90.0
    widget.camera.zoom(5)
    widget.reset_view()
    assert widget.camera.distance == pytest.approx(widget.camera.home_distance)
    with pytest.raises(ValueError, match="unknown view"):
        widget.set_view("under")


def _telemetry(profile: RobotProfile, angles: Mapping[str, float]) -> TelemetryPacket:
    records = []
    for motor in profile.motors.values():
        position = rad_to_ticks(motor, angles.get(motor.name, 0.0)) if motor.has_position else 0
        records.append(MotorRecord(device_id=motor.device_id, position=position))
    return TelemetryPacket(tick=1, motors=tuple(records))


def test_telemetry_frames_set_the_pose(widget: Model3DWidget, profile: RobotProfile) -> None:
    angles = {"flippers": 0.4, "waist": -1.0, "shoulder": 1.1, "elbow": 0.9, "gripper": 0.5}
    readings = read_telemetry(profile, _telemetry(profile, angles))
    assert readings["left_track"].angle_rad is None
    widget.on_telemetry(Frame(readings=readings, received_at=time.monotonic()))
    for name, value in angles.items():
        assert widget.live.position(name) == pytest.approx(value, abs=1e-4)
    assert widget.stale_joints() == frozenset()


def test_widget_follows_the_simulator_through_the_link(
    qtbot: QtBot, widget: Model3DWidget, profile: RobotProfile
) -> None:
    from ocu.link.live import UdpLink
    from ocu.qt.link import QtLink
    from ocu.sim.simulator import RobotSimulator

    simulator = RobotSimulator(
        profile, telemetry_hz=20.0, video_fps=0.0, initial_joints={"shoulder": 0.3, "elbow": -0.5}
    )
    simulator.start()
    link = QtLink(UdpLink(profile, simulator.address))
    link.telemetry_received.connect(widget.on_telemetry)
    try:
        link.start()
        qtbot.waitUntil(
            lambda: (
                abs(widget.live.position("shoulder") - 0.3) < 1e-3
                and abs(widget.live.position("elbow") + 0.5) < 1e-3
            ),
            timeout=DEADLINE_MS,
        )
        assert widget.stale_joints() == frozenset()
        link.link.set_command(Command(velocities={"shoulder": 0.4}))
        qtbot.waitUntil(lambda: widget.live.position("shoulder") > 0.45, timeout=DEADLINE_MS)
        link.link.set_command(Command())
        assert simulator.wait_until(lambda s: s.velocities["shoulder"] == 0.0, timeout=3.0)
        settled = simulator.state().joints_rad["shoulder"]
        qtbot.waitUntil(
            lambda: abs(widget.live.position("shoulder") - settled) < 1e-3, timeout=DEADLINE_MS
        )
    finally:
        link.shutdown()
        simulator.stop()
