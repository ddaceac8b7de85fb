"""The video panel against the real simulator: vendor and extended modes, offscreen Qt."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from PySide6.QtGui import QImage
from pytestqt.qtbot import QtBot

from ocu.console.model import ConsoleModel
from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.qt.console import ConsoleBinding
from ocu.qt.link import DecodedVideoFrame, QtLink
from ocu.records import CameraRequest
from ocu.sim.extended import jpeg_comment
from ocu.sim.simulator import RobotSimulator
from ocu.sim.video import parse_comment, quality_for_bitrate
from ocu.widgets.video import LIVE, NO_SIGNAL, NOT_STREAMED, VideoPanel, snapshot_name

WAIT_MS = 8000


def facts(frame: DecodedVideoFrame | None) -> dict[str, str]:
    """The simulator's burned-in facts of a displayed frame (its JPEG comment)."""
    if frame is None:
        return {}
    comment = jpeg_comment(frame.frame.jpeg)
    return parse_comment(comment) if comment else {}


@pytest.fixture
def start_panel(qtbot: QtBot, profile: RobotProfile, tmp_path: Path) -> Iterator[object]:
    links: list[QtLink] = []

    def start(model: ConsoleModel, udp: UdpLink) -> VideoPanel:
        link = QtLink(udp)
        links.append(link)
        ConsoleBinding(model, link, link)
        panel = VideoPanel(model, snapshot_dir=tmp_path / "snapshots")
        panel.set_link(link)
        qtbot.addWidget(panel)
        panel.resize(960, 720)
        panel.show()
        link.start()
        return panel

    yield start
    for link in links:
        link.shutdown()


@pytest.fixture
def vendor_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    sim = RobotSimulator(profile, telemetry_hz=10.0, video_fps=20.0, seed=1)
    sim.start()
    yield sim
    sim.stop()


def test_vendor_robot_one_camera_switched_through_the_rcp(
    qtbot: QtBot, profile: RobotProfile, vendor_sim: RobotSimulator, start_panel: object
) -> None:
    model = ConsoleModel(profile)
    udp = UdpLink(profile, vendor_sim.address, extension=True)
    panel: VideoPanel = start_panel(model, udp)  # type: ignore[operator]
    view = panel.view
    qtbot.waitUntil(lambda: view.stats(0).shown >= 3, timeout=WAIT_MS)
    assert facts(view.current_frame(0))["index"] == "0"

    panel.select_camera(2)
    assert vendor_sim.wait_until(lambda s: s.camera == 2, 3.0)
    qtbot.waitUntil(lambda: facts(view.current_frame(2)).get("index") == "2", timeout=WAIT_MS)
    assert view.signal_state(2) == LIVE
    assert view.signal_state(0) == NOT_STREAMED  # one camera at a time
    panel.set_grid(True)
    qtbot.waitUntil(lambda: view.grid, timeout=1000)

    panel.set_bitrate(400_000)
    assert vendor_sim.wait_until(lambda s: s.video_quality == quality_for_bitrate(400_000), 3.0)

    # The hellos went unanswered: everything the vendor protocol lacks says so.
    assert vendor_sim.state().foreign_count > 0
    assert not panel.extension_active
    assert panel.battery.text() == "Battery not reported"
    assert panel.headlight.text() == "Headlight: not reported"
    assert panel.attitude.text() == "Roll/pitch not reported"
    assert panel.protocol_label.text() == "Protocol: vendor"

    path = panel.save_snapshot()
    assert path is not None
    assert path.name.startswith("ocu-stereo-")
    image = QImage(str(path))
    assert (image.width(), image.height()) == (320, 240)


def test_extended_robot_four_streams_status_and_faults(
    qtbot: QtBot, profile: RobotProfile, start_panel: object
) -> None:
    sim = RobotSimulator(
        profile, extended=True, telemetry_hz=5.0, video_fps=0.0, battery_percent=55.0, seed=2
    )
    sim.start()
    try:
        model = ConsoleModel(profile)
        for k in range(4):
            model.set_stream_request(CameraRequest(k, 320, 240, 15))
        udp = UdpLink(profile, sim.address, extension=True, link_lost_after_s=1.0)
        panel: VideoPanel = start_panel(model, udp)  # type: ignore[operator]
        view = panel.view
        qtbot.waitUntil(lambda: panel.extension_active, timeout=WAIT_MS)
        assert view.grid  # the extension shows every camera at once
        assert panel.protocol_label.text() == "Protocol: <b>extended</b>"
        qtbot.waitUntil(lambda: all(view.stats(k).shown >= 8 for k in range(4)), timeout=WAIT_MS)
        for camera in range(4):
            shown = facts(view.current_frame(camera))
            assert shown["index"] == str(camera)
            assert shown["size"] == "320x240"
            assert view.signal_state(camera) == LIVE

        # Status: the robot's own battery and headlight, and roll/pitch.
        qtbot.waitUntil(lambda: panel.battery.charge_percent is not None, timeout=WAIT_MS)
        assert 50.0 <= (panel.battery.charge_percent or 0.0) <= 55.0
        assert not panel.battery.is_low
        assert panel.headlight.text() == "Headlight: off"
        assert panel.attitude.text() == "Roll +0.0°\nPitch +0.0°"
        model.set_torch(True)
        qtbot.waitUntil(lambda: panel.headlight.text() == "Headlight: ON", timeout=WAIT_MS)
        assert sim.extension is not None
        sim.extension.set_battery(12.0)
        qtbot.waitUntil(lambda: panel.battery.is_low, timeout=WAIT_MS)
        assert panel.battery.text().startswith("LOW Battery 12 %")

        # A camera that stops: NO SIGNAL there, the others go on.
        sim.extension.stop_camera(3)
        qtbot.waitUntil(lambda: view.signal_state(3) == NO_SIGNAL, timeout=WAIT_MS)
        shown_before = view.stats(0).shown
        qtbot.waitUntil(lambda: view.stats(0).shown > shown_before + 5, timeout=WAIT_MS)
        assert view.signal_state(0) == LIVE

        # Corrupt JPEGs are counted; the view keeps showing good frames.
        sim.extension.set_corrupt(0.5)
        link = panel.link
        assert link is not None
        qtbot.waitUntil(
            lambda: sum(link.decoder.stats(k).corrupt for k in range(3)) >= 3, timeout=WAIT_MS
        )
        shown_before = view.stats(1).shown
        qtbot.waitUntil(lambda: view.stats(1).shown > shown_before + 2, timeout=WAIT_MS)
        panel.refresh_counters()
        assert "corrupt" in " ".join(view.extra_lines.values())

        # The robot falls silent: after link_lost_after_s nothing is reported any more.
        sim.cut_link()
        qtbot.waitUntil(lambda: not panel.extension_active, timeout=WAIT_MS)
        assert panel.battery.text() == "Battery not reported"
        assert panel.headlight.text() == "Headlight: not reported"
        assert panel.status is None
    finally:
        sim.stop()


def test_snapshot_names_and_no_picture(qtbot: QtBot, profile: RobotProfile, tmp_path: Path) -> None:
    from datetime import datetime

    assert snapshot_name("front", datetime(2026, 1, 2, 3, 4, 5, 678_000)) == (
        "ocu-front-20260102-030405-678.png"
    )
    panel = VideoPanel(ConsoleModel(profile), snapshot_dir=tmp_path)
    qtbot.addWidget(panel)
    with qtbot.waitSignal(panel.snapshot_failed, timeout=1000):
        assert panel.save_snapshot() is None
    assert "no picture" in panel.message_label.text()
    assert panel.battery.text() == "Battery not reported"


def test_frames_are_decoded_at_the_cells_size_and_snapshots_saved_whole(
    qtbot: QtBot, profile: RobotProfile, start_panel: object
) -> None:
    from ocu.widgets.video_view import fit_rect

    sim = RobotSimulator(profile, extended=True, telemetry_hz=5.0, video_fps=0.0, seed=4)
    sim.start()
    try:
        model = ConsoleModel(profile)
        model.set_stream_request(CameraRequest(0, 640, 480, 15))
        for camera in (1, 2, 3):
            model.set_stream_request(CameraRequest(camera, 320, 240, 0))
        panel: VideoPanel = start_panel(model, UdpLink(profile, sim.address, extension=True))  # type: ignore[operator]
        panel.resize(640, 480)  # grid cells under half of 640x480
        view = panel.view
        qtbot.waitUntil(lambda: panel.extension_active, timeout=WAIT_MS)
        qtbot.waitUntil(lambda: view.stats(0).shown >= 3, timeout=WAIT_MS)
        link = panel.link
        assert link is not None

        def shown_at_cell_size() -> bool:
            frame = view.current_frame(0)
            if frame is None or frame.decoded is None:
                return False
            cell = view.cell_rects()[0]
            fit = fit_rect(cell, 640, 480)
            image = frame.image
            return abs(image.width() - fit.width()) <= 2 and abs(image.height() - fit.height()) <= 2

        qtbot.waitUntil(shown_at_cell_size, timeout=WAIT_MS)
        frame = view.current_frame(0)
        assert frame is not None
        assert frame.decoded is not None
        assert frame.decoded.source_px == (640, 480)
        assert frame.decoded.reduction >= 2  # libjpeg's DCT scaling did the first halving

        # A snapshot is the whole picture, not what the cell shows.
        view.set_selected(0)
        path = panel.save_snapshot()
        assert path is not None
        image = QImage(str(path))
        assert (image.width(), image.height()) == (640, 480)

        # Another camera alone on screen: camera 0 is no longer decoded at all.
        panel.set_grid(False)
        view.set_selected(1)
        hidden_before = link.decoder.stats(0).hidden
        qtbot.waitUntil(lambda: link.decoder.stats(0).hidden > hidden_before + 3, timeout=WAIT_MS)
    finally:
        sim.stop()
