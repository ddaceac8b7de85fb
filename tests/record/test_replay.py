"""Replay: the player without Qt, the Qt source against what a live LinkThread delivered."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from PySide6.QtCore import Qt
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication
from pytestqt.qtbot import QtBot

from ocu.link.core import LinkCore
from ocu.link.qt import LinkThread
from ocu.profile import RobotProfile
from ocu.record.player import ReplayCore, ReplayPlayer
from ocu.record.reader import Recording
from ocu.record.recorder import Recorder
from ocu.record.replay import ReplayBanner, ReplayControls, ReplaySource, format_time
from ocu.records import Command, LinkState, LinkStats, TelemetryFrame
from ocu.sim.simulator import RobotSimulator
from tests.record.helpers import Collector

DEADLINE_MS = 10_000


@pytest.fixture
def live_session(
    qtbot: QtBot, profile: RobotProfile, tmp_path: Path
) -> tuple[Path, list[TelemetryFrame]]:
    """A recording of a live LinkThread session and the telemetry its GUI side received."""
    sim = RobotSimulator(profile, telemetry_hz=20.0, video_fps=10.0, video_size=(160, 120))
    sim.start()
    thread = LinkThread(LinkCore(profile, sim.address))
    recorder = Recorder(profile)
    recorder.attach(thread.core)
    seen: list[TelemetryFrame] = []
    thread.telemetry_received.connect(seen.append)
    path = tmp_path / "live.mcap"
    recorder.start(path)
    thread.start_link()
    try:
        qtbot.waitUntil(lambda: len(seen) >= 5, timeout=DEADLINE_MS)
        thread.set_command(Command(velocities={"waist": 0.4, "shoulder": 0.3}))
        qtbot.waitUntil(lambda: len(seen) >= 30, timeout=DEADLINE_MS)
        thread.emergency_stop("test")
        qtbot.waitUntil(lambda: len(seen) >= 40, timeout=DEADLINE_MS)
    finally:
        thread.shutdown()
        sim.stop()
    recorder.stop()
    QApplication.processEvents()  # signals the link queued before it stopped
    return path, seen


def test_replay_reproduces_the_telemetry_the_gui_saw(
    qtbot: QtBot, profile: RobotProfile, live_session: tuple[Path, list[TelemetryFrame]]
) -> None:
    path, seen = live_session
    source = ReplaySource(path, profile)
    replayed: list[TelemetryFrame] = []
    states: list[LinkState] = []
    stats: list[LinkStats] = []
    safety: list[str] = []
    source.telemetry_received.connect(replayed.append)
    source.link_state_changed.connect(lambda state, _: states.append(state))
    source.stats_updated.connect(stats.append)
    source.safety_event.connect(safety.append)
    frames_ready: list[int] = []
    source.video_frame_ready.connect(frames_ready.append)
    source.start_link()
    try:
        source.set_speed(4.0)
        started = time.monotonic()
        with qtbot.waitSignal(source.finished, timeout=DEADLINE_MS):
            source.play()
        took_s = time.monotonic() - started
        qtbot.waitUntil(lambda: len(replayed) == len(seen), timeout=DEADLINE_MS)
        qtbot.waitUntil(lambda: bool(frames_ready), timeout=DEADLINE_MS)
        frame = source.take_video_frame(frames_ready[0])
        assert frame is not None
        assert not frame.image.isNull()
        assert frame.image.width() == 160
    finally:
        source.shutdown()
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


def test_player_seeks_restores_the_link_state_and_honours_speed(
    profile: RobotProfile, live_session: tuple[Path, list[TelemetryFrame]]
) -> None:
    path, seen = live_session
    collector = Collector()
    finished: list[bool] = []
    with Recording(path) as recording:
        player = ReplayPlayer(
            recording, recording.profile(), collector, on_finished=lambda: finished.append(True)
        )
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
            assert collector.wait(lambda: bool(finished))
            middle_wall = recording.start_ns / 1e9 + middle_s
            assert collector.telemetry
            assert all(f.wall_time >= middle_wall for f in collector.telemetry)
            assert collector.telemetry[-1].packet == seen[-1].packet
            assert player.position_s == pytest.approx(player.duration_s)
            # What the console reads of the link, answered for the replayed moment.
            core = ReplayCore(player)
            assert core.state == LinkState.CLOSED
            assert core.stats() == collector.stats[-1]
            assert core.command == Command(video_bitrate=core.command.video_bitrate)
            assert core.set_max_velocity("waist", 99.0) == profile.channels["waist"].hard_max
            assert core.video_stats().fragments == 0  # a vendor-protocol recording
            with pytest.raises(ValueError, match="speed"):
                player.set_speed(8.0)
        finally:
            player.stop()
            player.stop()


def test_controls_play_pause_speed_and_seek(
    qtbot: QtBot, live_session: tuple[Path, list[TelemetryFrame]]
) -> None:
    path, _ = live_session
    source = ReplaySource(path)
    controls = ReplayControls(source)
    banner = ReplayBanner(path)
    qtbot.addWidget(controls)
    qtbot.addWidget(banner)
    source.start_link()
    try:
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
        # A replay drives no robot: the command calls are accepted and do nothing.
        source.set_command(Command(velocities={"waist": 0.5}))
        source.emergency_stop()
    finally:
        source.shutdown()
        source.shutdown()


def test_format_time() -> None:
    assert format_time(0.0) == "0:00.0"
    assert format_time(61.26) == "1:01.3"
    assert format_time(3725.0) == "1:02:05.0"
