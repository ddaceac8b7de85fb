"""The Robot check dock: the probe's judgement of what the console's own link receives."""

from __future__ import annotations

from pytestqt.qtbot import QtBot

from ocu.calibrate.probe import MISMATCH
from ocu.profile import RobotProfile
from ocu.sim.simulator import RobotSimulator
from ocu.widgets.robot_check import LISTENING, OFF, STATE_MISMATCH, STATE_OK
from ocu.windows.main_window import MainWindow
from tests.calibrate.scrambled import scrambled_truth
from tests.windows.console_fixtures import DEADLINE_MS, ConsoleFactory, is_zero

# Listening (2 s) and a judgement after it (once a second).
CHECK_MS = DEADLINE_MS


def _show(console: MainWindow) -> None:
    console.robot_check_dock.show()
    console.robot_check_dock.raise_()


def test_the_simulator_checks_ok_and_the_check_sends_nothing(
    qtbot: QtBot, make_console: ConsoleFactory, profile: RobotProfile
) -> None:
    with RobotSimulator(profile, telemetry_hz=10.0, video_fps=2.0, extended=True) as sim:
        _check_ok(qtbot, make_console(sim, extension=True), sim)


def _check_ok(qtbot: QtBot, console: MainWindow, sim: RobotSimulator) -> None:
    panel = console.robot_check
    _show(console)
    qtbot.waitUntil(lambda: panel.state == STATE_OK, timeout=CHECK_MS)
    texts = [f.text for f in panel.findings]
    assert not [f for f in panel.findings if f.level == MISMATCH], texts
    assert any("telemetry packet(s)" in t and "parse" in t for t in texts), texts
    # The extension's datagrams (status, scans, video fragments) are known, not contradictions.
    assert any("protocol extension (status)" in t for t in texts), texts
    assert any("Positions inside the profile's limits" in t for t in texts), texts
    assert panel.list.count() == len(panel.findings)
    assert "OK" in panel.verdict.text()
    # Nothing the console sent while it checked moved the robot.
    received = sim.received_commands()
    assert received
    assert all(is_zero(rcp) for rcp in received)
    # Check again starts afresh; a disconnect turns the check off.
    panel.again.click()
    assert panel.state == LISTENING
    assert panel.list.count() == 0
    qtbot.waitUntil(lambda: panel.state == STATE_OK, timeout=CHECK_MS)
    console._on_connection(False)
    assert panel.state == OFF


def test_a_scrambled_robot_is_a_mismatch_that_names_the_keys(
    qtbot: QtBot, make_console: ConsoleFactory, profile: RobotProfile
) -> None:
    truth = scrambled_truth(5)
    with RobotSimulator(truth, telemetry_hz=10.0, video_fps=0.0) as sim:
        console = make_console(sim)
        panel = console.robot_check
        _show(console)
        qtbot.waitUntil(lambda: panel.state == STATE_MISMATCH, timeout=CHECK_MS)
        keys = {f.key for f in panel.findings if f.level == MISMATCH}
        # The zero offsets are anywhere in the u32 range: every joint reads outside its limits.
        joints = [m.name for m in profile.motors.values() if m.limits_deg is not None]
        assert {f"motors.{name}.zero_offset_ticks" for name in joints} <= keys, keys
        assert "MISMATCH" in panel.verdict.text()
        sentence = next(f.text for f in panel.findings if f.key and "zero_offset" in f.key)
        assert "outside its limits" in sentence
        assert "ocu calibrate" in sentence
