"""Replay: the read-only link against what the live link delivered, then its Qt side."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from PySide6.QtCore import Qt
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.qt.link import QtLink
from ocu.qt.replay import ReplayController
from ocu.record.recorder import Recorder
from ocu.record.replay_link import ReplayLink
from ocu.records import Command, LinkState, TelemetryFrame
from ocu.sim.simulator import RobotSimulator
from ocu.widgets.replay import ReplayBanner, ReplayControls, format_time
from tests.record.helpers import Collector

DEADLINE_MS = 10_000


@pytest.fixture
def live_session(profile: RobotProfile, tmp_path: Path) -> tuple[Path, list[TelemetryFrame]]:
    """A recording of a live link session and the telemetry the link delivered."""
    sim = RobotSimulator(profile, telemetry_hz=20.0, video_fps=10.0, video_size=(160, 120))
    sim.start()
    live = Collector()
    link = UdpLink(profile, sim.address, listener=live, gui_alive_timeout_s=None)
    recorder = Recorder(profile)
    recorder.attach(link)
    path = tmp_path / "live.mcap"
    recorder.start(path)
    link.start()
    try:
        assert live.wait(lambda: len(live.telemetry) >= 5)
        link.set_command(Command(velocities={"waist": 0.4, "shoulder": 0.3}))
        assert live.wait(lambda: len(live.telemetry) >= 30)
        link.emergency_stop("test")
        assert live.wait(lambda: len(live.telemetry) >= 40)
    finally:
        link.shutdown()
        sim.stop()
    recorder.stop()
    return path, live.telemetry


def test_replay_reproduces_the_telemetry_the_live_link_delivered(
    profile: RobotProfile, live_session: tuple[Path, list[TelemetryFrame]]
) -> None:
    path, seen = live_session
    collector = Collector()
    source = ReplayLink(path, profile, on_finished=collector.mark_finished)
    source.subscribe(collector)
    source.start()
    try:
        source.set_speed(4.0)
        started = time.monotonic()
        source.play()
        assert collector.wait(lambda: collector.finished)
        took_s = time.monotonic() - started
        assert collector.wait(lambda: len(collector.telemetry) == len(seen))
        assert collector.video
        assert source.read_only
    finally:
        source.shutdown()
    replayed = collector.telemetry
    states, stats, safety = collector.states, collector.stats, collector.safety
    assert [(f.packet, f.readings) for f in replayed] == [(f.packet, f.readings) for f in seen]
    # The recording's wall clock, not the replay's: each frame at its recorded moment. (The
    # live side read time.time() itself; a VM may step its wall clock meanwhile, so the
    # frames are compared with the typical offset, and one step is forgiven.)
    offsets = sorted(
        again.wall_time - live.wall_time for live, again in zip(seen, replayed, strict=True)
    )
    typical = offsets[len(offsets) // 2]
    assert abs(typical) < 0.05
    near = [abs(offset - typical) < 0.05 for offset in offsets]
    assert sum(near) >= 0.9 * len(near)
    assert any(f.readings["waist"].speed_rad_s > 0.3 for f in replayed)
    assert states[0] == LinkState.CONNECTED
    assert states[-1] == LinkState.CLOSED
    assert safety == ["EMERGENCY STOP (test)"]
    assert stats
    assert stats[-1].telemetry >= len(seen) - 10
    # 4x: the recording's duration in a quarter of the time (loosely: two shared cores).
    assert took_s < source.duration_s / 4.0 + 1.0


def test_the_replay_seeks_restores_the_link_state_and_honours_speed(
    live_session: tuple[Path, list[TelemetryFrame]],
) -> None:
    path, seen = live_session
    collector = Collector()
    player = ReplayLink(path, on_finished=collector.mark_finished)
    player.subscribe(collector)
    player.start()
    try:
        middle_s = player.duration_s / 2
        player.seek(middle_s)
        assert collector.wait(lambda: len(collector.stats) == 1)
        assert collector.states == [LinkState.CONNECTED]
        assert collector.telemetry == []
        assert not player.playing
        player.set_speed(2.0)
        player.play()
        assert collector.wait(lambda: collector.finished)
        middle_wall = player.start_ns / 1e9 + middle_s
        assert collector.telemetry
        assert all(f.wall_time >= middle_wall for f in collector.telemetry)
        assert collector.telemetry[-1].packet == seen[-1].packet
        assert player.position_s == pytest.approx(player.duration_s)
        # The Link interface, answered for the replayed moment; commands go nowhere.
        assert player.state == LinkState.CLOSED
        assert player.stats() == collector.stats[-1]
        assert player.command == Command(video_bitrate=player.command.video_bitrate)
        assert player.video_stats().fragments == 0  # a vendor-protocol recording
        player.set_command(Command(velocities={"waist": 0.5}))
        player.emergency_stop()
        assert not player.command.is_motion
        with pytest.raises(ValueError, match="speed"):
            player.set_speed(8.0)
    finally:
        player.shutdown()
        player.shutdown()


def test_controls_play_pause_speed_and_seek(
    qtbot: QtBot, live_session: tuple[Path, list[TelemetryFrame]]
) -> None:
    path, _ = live_session
    replay = ReplayLink(path)
    link = QtLink(replay)
    source = ReplayController(replay)
    controls = ReplayControls(source)
    banner = ReplayBanner(path)
    qtbot.addWidget(controls)
    qtbot.addWidget(banner)
    frames_ready: list[int] = []
    link.video_frame_ready.connect(frames_ready.append)
    link.start()
    try:
        # The video of a replay is decoded off the GUI thread like live video.
        source.set_speed(4.0)
        with qtbot.waitSignal(source.finished, timeout=DEADLINE_MS):
            source.play()
        qtbot.waitUntil(lambda: bool(frames_ready), timeout=DEADLINE_MS)
        frame = link.take_video_frame(frames_ready[0])
        assert frame is not None
        assert not frame.image.isNull()
        assert frame.image.width() == 160
        source.set_speed(1.0)
        source.seek(0.0)
        assert "REPLAY" in banner.text()
        assert controls.badge.text() == "REPLAY"
        assert controls.time_label.text() == f"0:00.0 / {format_time(source.duration_s)}"
        with qtbot.waitSignal(source.playing_changed, timeout=DEADLINE_MS) as playing:
            QTest.mouseClick(controls.play_button, Qt.MouseButton.LeftButton)
        assert playing.args == [True]
        assert controls.play_button.text() == "Pause"
        controls.speed_box.setCurrentIndex(controls.speed_box.findText("0.25x"))
        assert source.speed == 0.25
        QTest.mouseClick(controls.play_button, Qt.MouseButton.LeftButton)
        qtbot.waitUntil(lambda: not source.playing, timeout=DEADLINE_MS)
        with qtbot.waitSignal(source.finished, timeout=DEADLINE_MS):
            source.play()
            controls.slider.setFocus()
            QTest.keyClick(controls.slider, Qt.Key.Key_End)
        qtbot.waitUntil(
            lambda: controls.slider.value() == controls.slider.maximum(), timeout=DEADLINE_MS
        )
    finally:
        source.stop()
        link.shutdown()
        link.shutdown()


def test_format_time() -> None:
    assert format_time(0.0) == "0:00.0"
    assert format_time(61.26) == "1:01.3"
    assert format_time(3725.0) == "1:02:05.0"
