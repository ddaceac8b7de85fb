"""The console with its control core in a process of its own (`ocu --core-process`).

The window is real (offscreen Qt), the core is a real child process (ocu.core_process) on a
real UDP socket to the simulator in this process; what is checked is what the simulator
received.
"""

from __future__ import annotations

import math
import os
import signal
import time
from pathlib import Path

from PySide6.QtCore import QSettings, Qt, QTimer
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QWidget
from pytestqt.qtbot import QtBot

from ocu.core_process import CoreSpec
from ocu.gamepad.calibration import CALIBRATION_FILE_NAME, CalibrationStore
from ocu.gamepad.mapping import load_pad_mapping, parse_pad_mapping
from ocu.gamepad.teleop import PadStatus
from ocu.profile import RobotProfile
from ocu.records import LinkState
from ocu.sim.simulator import RobotSimulator
from ocu.windows.main_window import MainWindow
from ocu.windows.remote_control import CORE_ENDED, RemoteControl
from tests.windows.console_fixtures import (
    DEADLINE_MS,
    ConsoleFactory,
    is_zero,
    wait_sim,
    wait_zeros,
)

# The simulator's watchdog zeroes the motors after 1 s without a command.
WATCHDOG_MS = 3000


def test_keys_drive_and_space_stops_through_the_core_process(
    qtbot: QtBot, make_console: ConsoleFactory, sim: RobotSimulator
) -> None:
    console: MainWindow = make_console(sim, core=True)
    assert isinstance(console.control, RemoteControl)
    assert console.control.process.pid != os.getpid()
    QTest.keyPress(console, Qt.Key.Key_Y)
    state = wait_sim(qtbot, sim, lambda s: s.velocities["shoulder"] > 0, "the shoulder moving")
    assert state.velocities["shoulder"] == console.model.hotkey_speed("shoulder")
    QTest.keyRelease(console, Qt.Key.Key_Y)
    wait_zeros(qtbot, sim, "zeros after the release")
    QTest.keyPress(console, Qt.Key.Key_W)
    wait_sim(qtbot, sim, lambda s: not s.all_stopped, "driving")
    QTest.keyPress(console, Qt.Key.Key_Space)
    wait_zeros(qtbot, sim, "zeros after Space")
    qtbot.waitUntil(lambda: console.model.estopped, timeout=DEADLINE_MS)
    QTest.keyRelease(console, Qt.Key.Key_W)
    QTest.keyRelease(console, Qt.Key.Key_Space)


def test_a_position_target_is_reached_by_the_core(
    qtbot: QtBot, make_console: ConsoleFactory, sim: RobotSimulator
) -> None:
    console: MainWindow = make_console(sim, core=True)
    qtbot.waitUntil(lambda: console.model.robot.last_telemetry_at is not None, timeout=DEADLINE_MS)
    targets_seen: list[dict[str, float]] = []
    console.model.events.targets_changed.connect(targets_seen.append)
    target = sim.state().joints_rad["neck"] + math.radians(20.0)
    console.model.set_target("neck", target)
    assert targets_seen, "the call's event came before it returned"
    assert "neck" in targets_seen[-1]
    wait_sim(qtbot, sim, lambda s: s.velocities["neck"] > 0.0, "the neck moving")
    wait_zeros(qtbot, sim, "the neck stopped at its target", timeout_ms=3 * DEADLINE_MS)
    error_deg = math.degrees(sim.state().joints_rad["neck"] - target)
    assert abs(error_deg) <= 1.0, f"stopped {error_deg:+.2f} deg from its target"
    qtbot.waitUntil(lambda: not console.model.targets, timeout=DEADLINE_MS)
    # The views' reads answer from the core: the timing label shows its control thread.
    console.control.show_timing()
    assert "(core)" in console.control.label.text()


def test_closing_the_window_ends_the_core_with_zeros_last(
    qtbot: QtBot, make_console: ConsoleFactory, sim: RobotSimulator
) -> None:
    console: MainWindow = make_console(sim, core=True)
    control = console.control
    assert isinstance(control, RemoteControl)
    QTest.keyPress(console, Qt.Key.Key_U)
    wait_sim(qtbot, sim, lambda s: s.velocities["elbow"] > 0, "the elbow moving")
    console.close()
    assert control.process.process.wait(10) == 0
    wait_zeros(qtbot, sim, "zeros last", more=0)


def test_a_killed_core_shows_link_lost_and_the_robot_stops_by_itself(
    qtbot: QtBot, make_console: ConsoleFactory, sim: RobotSimulator
) -> None:
    console: MainWindow = make_console(sim, core=True)
    control = console.control
    assert isinstance(control, RemoteControl)
    QTest.keyPress(console, Qt.Key.Key_W)
    wait_sim(qtbot, sim, lambda s: not s.all_stopped, "driving")
    os.kill(control.process.pid, signal.SIGKILL)
    qtbot.waitUntil(lambda: console.link_status.state == LinkState.LOST, timeout=DEADLINE_MS)
    assert CORE_ENDED in console.event_log.item(console.event_log.count() - 1).text()
    # Nobody commands the robot any more: its own watchdog stops it.
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "the robot stopped", timeout_ms=WATCHDOG_MS)
    QTest.keyRelease(console, Qt.Key.Key_W)
    console.close()  # the window still closes cleanly


VIRTUAL_PAD = "vpad=ocu.gamepad.virtual:core_virtual_pad"
STICK_UP = -32768


def test_the_pad_read_in_the_core_drives_and_space_stops_it(
    qtbot: QtBot, profile: RobotProfile, settings: QSettings, tmp_path: Path, sim: RobotSimulator
) -> None:
    # The core reads the pad itself (its "pad" part); SDL's virtual pads are a process's own,
    # so the virtual pad is plugged into the core too, and moved through its pipe.
    host, port = sim.address
    mapping = parse_pad_mapping(
        {"options": {"stall_timeout_ms": 400}}, profile, load_pad_mapping(profile), "test"
    )
    window = MainWindow(
        profile,
        None,
        "simulator",
        settings,
        pad_mapping=mapping,
        pad_calibrations=CalibrationStore(tmp_path / CALIBRATION_FILE_NAME),
        core=CoreSpec(profile, "engineer", f"{host}:{port}", parts=(VIRTUAL_PAD,)),
    )
    qtbot.addWidget(window)
    try:
        window.show()
        window.activateWindow()
        qtbot.waitUntil(window.isActiveWindow, timeout=DEADLINE_MS)
        qtbot.waitUntil(
            lambda: window.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS
        )
        assert isinstance(window.control, RemoteControl)
        assert window.gamepad is None  # no poller in the GUI's process
        pad = window.control.process.part("vpad")
        qtbot.waitUntil(lambda: window.teleop.status is PadStatus.READY, timeout=DEADLINE_MS)
        qtbot.waitUntil(lambda: window.pad_indicator.text() == "PAD ready", timeout=DEADLINE_MS)
        pad.set_axis("lefty", STICK_UP)
        pad.set_button("leftshoulder", True)
        qtbot.waitUntil(lambda: window.teleop.engaged, timeout=DEADLINE_MS)
        # The deadman pressed with the stick already forward: nothing moves until it rests.
        pad.set_axis("lefty", 0)
        qtbot.waitUntil(lambda: window.teleop.value("lefty") == 0.0, timeout=DEADLINE_MS)
        pad.set_axis("lefty", STICK_UP)
        wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0, "driving on the pad")
        QTest.keyPress(window, Qt.Key.Key_Space)
        wait_zeros(qtbot, sim, "zeros after Space, the stick still forward", more=5)
        QTest.keyRelease(window, Qt.Key.Key_Space)
        pad.set_button("leftshoulder", False)
    finally:
        window.shutdown()


def test_a_stalled_gui_thread_stops_what_it_fed_in_the_core(
    qtbot: QtBot, make_console: ConsoleFactory, sim: RobotSimulator, profile: RobotProfile
) -> None:
    console: MainWindow = make_console(sim, core=True)
    QTest.keyPress(console, Qt.Key.Key_W)
    wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0, "driving forward")
    stall_s = profile.link.gui_alive_timeout_s * 2.4
    stalled: list[float] = []

    def stall() -> None:
        # The GUI's thread runs no event and posts no heartbeat (a long computation).
        stalled.append(time.monotonic())
        time.sleep(stall_s)
        stalled.append(time.monotonic())

    QTimer.singleShot(0, stall)
    qtbot.waitUntil(lambda: len(stalled) == 2, timeout=DEADLINE_MS)
    start, end = stalled
    zeros = [r for r in sim.received_commands() if r.time_s >= start and is_zero(r)]
    assert zeros, "no zeros during the stall"
    assert zeros[0].time_s < end, "zeros only after the stall"
    assert not sim.state().watchdog_stopped, "the robot's watchdog stopped it, not the core"
    wait_zeros(qtbot, sim, "nothing resumes after the stall, W still held")
    QTest.keyRelease(console, Qt.Key.Key_W)


def test_focus_loss_stops_through_the_core(
    qtbot: QtBot, make_console: ConsoleFactory, sim: RobotSimulator
) -> None:
    console: MainWindow = make_console(sim, core=True)
    QTest.keyPress(console, Qt.Key.Key_W)
    wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0, "driving forward")
    other = QWidget()
    qtbot.addWidget(other)
    other.show()
    other.activateWindow()
    qtbot.waitUntil(other.isActiveWindow, timeout=DEADLINE_MS)
    wait_zeros(qtbot, sim, "another window took the focus")
    assert console.model.held_keys == frozenset()


def test_disconnect_and_connect_again_through_the_core(
    qtbot: QtBot, make_console: ConsoleFactory, sim: RobotSimulator
) -> None:
    console: MainWindow = make_console(sim, core=True)
    first = sim.state().client
    console.model.set_connected(False)
    qtbot.waitUntil(lambda: console.link is None, timeout=DEADLINE_MS)
    wait_zeros(qtbot, sim, "zeros when the link stopped", more=0)
    console.model.set_connected(True)
    qtbot.waitUntil(lambda: console.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS)
    assert sim.state().client != first  # a new link: a new socket
    QTest.keyPress(console, Qt.Key.Key_W)
    wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0, "driving after reconnecting")
    QTest.keyRelease(console, Qt.Key.Key_W)
    wait_zeros(qtbot, sim, "zeros after the release")
