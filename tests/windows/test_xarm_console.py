"""The console on the xArm 1S (issue 23) through the same window as the other robots.

The window is real (offscreen), the xArm simulator is real (ocu.sim.xarm on a
pseudo-terminal), the hardware is the "xarm" plug-in over XarmLink (pyserial). What is
checked is what the SIMULATOR received: keys of the xArm's key map
(ocu/profiles/xarm/hotkeys.toml) stream jog moves to a servo, the release sends the stop
move, Space holds every servo; the Arm dock is there, over the xArm's URDF.
"""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from PySide6.QtCore import QSettings, Qt
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication, QDockWidget
from pytestqt.qtbot import QtBot

from ocu.core_process import CoreSpec
from ocu.gamepad.mapping import load_pad_mapping
from ocu.hardware.xarm import XARM_CAPABILITIES, ConsoleLinks
from ocu.hotkeys import HoldBinding, load_key_map
from ocu.profile.xarm import XarmProfile, load_xarm_profile
from ocu.profile.xarm_robot import xarm_robot_profile
from ocu.records import LinkState
from ocu.sim.xarm import XarmSimulator, XarmSnapshot
from ocu.windows.main_window import MainWindow, MissingCapabilityError
from tests.windows.console_fixtures import DEADLINE_MS

ROOT = Path(__file__).resolve().parents[2]
BASE, GRIPPER = 6, 1  # servo IDs


@pytest.fixture
def arm() -> XarmProfile:
    return load_xarm_profile("xarm1s")


@pytest.fixture
def links(arm: XarmProfile) -> Iterator[ConsoleLinks]:
    console_links = ConsoleLinks(arm, xarm_robot_profile(arm), None)
    yield console_links
    console_links.close()


@pytest.fixture(params=[False, True], ids=["in-process", "core-process"])
def xarm_console(
    links: ConsoleLinks, settings: QSettings, qtbot: QtBot, request: pytest.FixtureRequest
) -> Iterator[MainWindow]:
    """The console on the xArm simulator's pseudo-terminal; in its core-process form the
    "xarm" plug-in opens it from the core's process (ocu.core_process)."""
    profile = links.profile
    core = CoreSpec(profile, "xarm", links.path, options={"arm": links.arm})
    window = MainWindow(
        profile,
        links.make_link,
        links.where,
        settings,
        load_key_map(profile),
        pad_mapping=load_pad_mapping(profile),
        hardware_for=links.hardware_for,
        capabilities=XARM_CAPABILITIES,
        core=core if request.param else None,
    )
    qtbot.addWidget(window)
    window.show()
    qtbot.waitUntil(lambda: window.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS)
    yield window
    window.shutdown()
    QApplication.processEvents()


def wait_sim(qtbot: QtBot, sim: XarmSimulator, check: object, what: str) -> XarmSnapshot:
    assert callable(check)
    try:
        qtbot.waitUntil(lambda: bool(check(sim.snapshot())), timeout=DEADLINE_MS)
    except AssertionError:
        raise AssertionError(f"the xArm simulator: not {what}; {sim.snapshot()}") from None
    return sim.snapshot()


def stop_move(snapshot: XarmSnapshot, servo: int) -> bool:
    move = snapshot.last_move
    return move is not None and move.duration_ms == 0 and servo in dict(move.positions)


def test_keys_jog_a_servo_the_release_and_space_stop_it(
    xarm_console: MainWindow, links: ConsoleLinks, qtbot: QtBot
) -> None:
    window, sim = xarm_console, links.simulator
    assert sim is not None
    window.activateWindow()
    window.velocity_panel.setFocus()
    pressed_at = sim.snapshot().time
    QTest.keyPress(window, Qt.Key.Key_Q)  # base + (the xArm's key map)
    moving = wait_sim(qtbot, sim, lambda s: s.setpoints[BASE] > 510, "the base turning")
    jogs = [m for _, m in sim.board.moves_since(pressed_at) if m.duration_ms == 150]
    assert jogs, "no jog move (150 ms)"
    assert all(dict(m.positions).keys() == {BASE} for m in jogs)
    assert all(moving.targets[s] == 500 for s in (1, 2, 3, 4, 5))
    QTest.keyRelease(window, Qt.Key.Key_Q)
    released = wait_sim(qtbot, sim, lambda s: stop_move(s, BASE), "the stop move")
    # Where it was when the stop was sent: the setpoint moves on until the frame is read
    # (the simulator's thread shares this process's interpreter with the window's
    # painting), so within one jog period's travel of it, not a whole jog move ahead.
    ends = [
        dict(m.positions)[BASE]
        for _, m in sim.board.moves_since(pressed_at)
        if m.duration_ms == 150
    ]
    period_travel = max((abs(b - a) for a, b in itertools.pairwise(ends)), default=1.0)
    assert abs(released.targets[BASE] - released.setpoints[BASE]) <= max(period_travel, 1.0)
    wait_sim(qtbot, sim, lambda s: s.setpoints[BASE] == released.targets[BASE], "stopped")
    QTest.keyPress(window, Qt.Key.Key_P)  # gripper +
    wait_sim(qtbot, sim, lambda s: s.setpoints[GRIPPER] > 510, "the gripper opening")
    QTest.keyClick(window, Qt.Key.Key_Space)
    held = wait_sim(
        qtbot,
        sim,
        lambda s: stop_move(s, GRIPPER) and len(s.last_move.positions) == 6,
        "every servo held (the e-stop)",
    )
    wait_sim(qtbot, sim, lambda s: s.setpoints == held.targets, "every servo stopped")
    QTest.keyRelease(window, Qt.Key.Key_P)
    assert window.model.estopped
    # Nothing after the e-stop: three more reads and no jog move.
    assert held.last_move_at is not None
    reads = held.position_reads
    wait_sim(qtbot, sim, lambda s: s.position_reads >= reads + 3, "reading on")
    assert all(m.duration_ms == 0 for _, m in sim.board.moves_since(held.last_move_at))


def test_the_window_shows_what_an_xarm_has(xarm_console: MainWindow) -> None:
    window = xarm_console
    names = {dock.objectName() for dock in window.findChildren(QDockWidget)}
    assert {"velocity_dock", "joint_position_dock", "arm_dock"} <= names
    assert not names & {"video_dock", "map_dock", "calibration_dock"}
    # The Arm dock over the xArm's URDF: seed 003's closed-form IK, not the numeric solver.
    assert window.arm_panel is not None
    assert window.model.arm is not None
    for view in ("video_panel", "map_dock", "calibration_panel"):
        with pytest.raises(MissingCapabilityError):
            getattr(window, view)
    joints = [window.joint_panel.table.cell_text(r, "joint") for r in range(6)]
    assert joints == ["base", "shoulder", "elbow", "wrist_pitch", "wrist_roll", "gripper"]
    assert load_key_map(xarm_robot_profile(load_xarm_profile("xarm1s"))).hold["Q"] == (
        HoldBinding("base", 1)
    )


@pytest.mark.parametrize(
    "core", [["--in-process"], []], ids=["in-process", "core-process (the default)"]
)
def test_ocu_profile_xarm1s_opens_the_console_on_the_xarm_simulator(
    tmp_path: Path, core: list[str]
) -> None:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "PYTHONPATH": str(ROOT)}
    with subprocess.Popen(
        [
            *(sys.executable, "-m", "ocu", "--profile", "xarm1s"),
            *("--config-dir", str(tmp_path), "--no-gamepad", *core),
        ],
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    ) as console:
        assert console.stderr is not None
        lines: list[str] = []
        deadline = time.monotonic() + 120.0
        while not any("xArm link connected: xArm board on /dev/pts/" in x for x in lines):
            assert time.monotonic() < deadline, "".join(lines)
            line = console.stderr.readline()
            assert line, "".join(lines)  # it exited before connecting
            lines.append(line)
        console.send_signal(signal.SIGTERM)
        _, rest = console.communicate(timeout=60)
    assert console.returncode == 0, "".join(lines) + rest
    assert "link stopped (zeros sent last)" in rest
    own = "control core: a process of its own" in "".join(lines) + rest
    assert own == (not core), "".join(lines) + rest
    missing = subprocess.run(
        [sys.executable, "-m", "ocu", "--profile", "xarm1s", "--robot", str(tmp_path / "tty")],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        check=False,
    )
    assert missing.returncode == 1
    assert "no serial device" in missing.stderr
