"""The one Qt adapter over any Link: signals, mailboxes, the heartbeat, shutdown."""

from __future__ import annotations

from pytestqt.qtbot import QtBot

from ocu.link.live import UdpLink
from ocu.profile import RobotProfile
from ocu.qt.link import DecodedVideoFrame, QtLink
from ocu.records import LinkState
from ocu.sim.simulator import RobotSimulator


def test_the_qt_adapter_emits_signals_and_stops(qtbot: QtBot, profile: RobotProfile) -> None:
    sim = RobotSimulator(profile, telemetry_hz=20.0, video_fps=20.0)
    sim.start()
    link = UdpLink(profile, sim.address)
    thread = QtLink(link)
    try:
        with (
            qtbot.waitSignal(thread.telemetry_received, timeout=3000) as telemetry,
            qtbot.waitSignal(thread.link_state_changed, timeout=3000) as state,
        ):
            thread.start()
        assert "waist" in telemetry.args[0].readings
        assert state.args[0] == LinkState.CONNECTED
        with qtbot.waitSignal(thread.video_frame_received, timeout=3000) as video:
            pass
        frame = video.args[0]
        assert isinstance(frame, DecodedVideoFrame)
        assert not frame.image.isNull()
        assert frame.image.width() == 320
        with qtbot.waitSignal(thread.stats_updated, timeout=3000) as stats:
            pass
        assert stats.args[0].telemetry > 0
        # The GUI thread's heartbeat keeps motion going past the 0.5 s watchdog.
        thread.link.set_velocities(neck=0.3)
        qtbot.wait(800)
        assert thread.link.command.is_motion
    finally:
        thread.shutdown()
        thread.shutdown()
        # The closing zeros may still be in the simulator's socket: let it read them first.
        sim.wait_until(lambda s: s.all_stopped, 3.0)
        sim.stop()
    assert not link.loop.running
    assert sim.received_commands()[-1].packet.axes == (0,) * 16
