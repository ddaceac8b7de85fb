"""The console on a second robot: a Universal Robots arm (issue 22) through the same window.

The window is real (offscreen), the UR simulator is real (ocu.sim.ur, TCP on 127.0.0.1), the
hardware is the "ur" plug-in over UrLink. What is checked is what the SIMULATOR does: keys of
the UR's own key map (ocu/profiles/ur/hotkeys.toml) move its joints, a release stops them,
Space brings the arm to rest; and the window shows only what a UR has.
"""

from __future__ import annotations

import math
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PySide6.QtCore import QSettings, Qt
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication, QCheckBox, QDockWidget
from pytestqt.qtbot import QtBot

from ocu.core.hardware import HardwareComponent
from ocu.core_process import CoreSpec
from ocu.gamepad.mapping import load_pad_mapping
from ocu.hardware.ur import UR_CAPABILITIES, ur_component
from ocu.hotkeys import HoldBinding, load_key_map
from ocu.kinematics.rpy import angle_between, describe_pose, pose_from_rpy, rpy_of
from ocu.link.base import Link
from ocu.link.ur import UrLink
from ocu.profile import RobotProfile
from ocu.profile.ur import UrArmProfile, load_ur_profile
from ocu.profile.ur_robot import ur_robot_profile
from ocu.records import LinkState
from ocu.sim.ur import UrSimSnapshot, UrSimulator
from ocu.windows.main_window import MainWindow, MissingCapabilityError
from tests.windows.console_fixtures import DEADLINE_MS

ROOT = Path(__file__).resolve().parents[2]
SHOULDER_LIFT = 1  # the simulator's joint index (base to tool)


@pytest.fixture
def arm() -> UrArmProfile:
    return load_ur_profile("ur5e")


@pytest.fixture
def ur_sim(arm: UrArmProfile) -> Iterator[UrSimulator]:
    simulator = UrSimulator(arm, host="127.0.0.1", ports=(0, 0, 0))
    simulator.start()
    yield simulator
    simulator.stop()


@pytest.fixture(params=[False, True], ids=["in-process", "core-process"])
def ur_console(
    arm: UrArmProfile,
    ur_sim: UrSimulator,
    settings: QSettings,
    qtbot: QtBot,
    request: pytest.FixtureRequest,
) -> Iterator[MainWindow]:
    """The console on the UR simulator; in its core-process form the "ur" plug-in runs in
    the core's process (ocu.core_process) and talks to the simulator over TCP from there."""
    profile = ur_robot_profile(arm)
    ports = (ur_sim.ports["primary"], ur_sim.ports["secondary"], ur_sim.ports["realtime"])
    core = CoreSpec(profile, "ur", "127.0.0.1", options={"arm": arm, "ports": ports})

    def make_link() -> Link:
        return UrLink(arm, "127.0.0.1", profile=profile, ports=ports)

    def hardware_for(link: Link) -> HardwareComponent:
        assert isinstance(link, UrLink)
        return ur_component(link)

    window = MainWindow(
        profile,
        make_link,
        "UR simulator",
        settings,
        load_key_map(profile),
        pad_mapping=load_pad_mapping(profile),
        hardware_for=hardware_for,
        capabilities=UR_CAPABILITIES,
        core=core if request.param else None,
    )
    qtbot.addWidget(window)
    window.show()
    qtbot.waitUntil(lambda: window.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS)
    yield window
    window.shutdown()
    QApplication.processEvents()


def wait_sim(qtbot: QtBot, sim: UrSimulator, check: object, what: str) -> None:
    assert callable(check)
    try:
        qtbot.waitUntil(lambda: bool(check(sim.snapshot())), timeout=DEADLINE_MS)
    except AssertionError:
        raise AssertionError(f"the UR simulator: not {what}; {sim.snapshot()}") from None


def test_the_urs_keys_move_its_joints_and_space_brings_it_to_rest(
    ur_console: MainWindow, ur_sim: UrSimulator, qtbot: QtBot
) -> None:
    window = ur_console
    window.activateWindow()
    window.velocity_panel.setFocus()
    QTest.keyPress(window, Qt.Key.Key_Y)  # shoulder_lift_joint + (the UR's key map)
    wait_sim(qtbot, ur_sim, lambda s: s.qd[SHOULDER_LIFT] > 0.0, "the shoulder lifting")
    assert all(v == 0.0 for i, v in enumerate(ur_sim.snapshot().qd) if i != SHOULDER_LIFT)
    QTest.keyRelease(window, Qt.Key.Key_Y)
    wait_sim(qtbot, ur_sim, lambda s: all(v == 0.0 for v in s.qd), "at rest after the release")
    QTest.keyPress(window, Qt.Key.Key_P)  # wrist_3_joint +
    wait_sim(qtbot, ur_sim, lambda s: s.qd[5] > 0.0, "wrist 3 turning")
    QTest.keyClick(window, Qt.Key.Key_Space)
    wait_sim(qtbot, ur_sim, lambda s: s.program == "stopj", "stopj running (the e-stop)")
    wait_sim(qtbot, ur_sim, lambda s: all(v == 0.0 for v in s.qd), "at rest after Space")
    QTest.keyRelease(window, Qt.Key.Key_P)
    assert window.model.estopped


def test_the_window_shows_what_a_ur_has_and_nothing_of_the_engineer(
    ur_console: MainWindow,
) -> None:
    window = ur_console
    names = {dock.objectName() for dock in window.findChildren(QDockWidget)}
    assert {"velocity_dock", "joint_position_dock"} <= names
    assert not names & {"video_dock", "map_dock", "calibration_dock"}
    for view in ("video_panel", "map_dock", "calibration_panel"):
        with pytest.raises(MissingCapabilityError):
            getattr(window, view)
    # No torch box, no switches, no zones badge in the status bar.
    torch = [box for box in window.findChildren(QCheckBox) if "Torch" in box.text()]
    assert not [box for box in torch if box.isVisibleTo(window)]
    assert not window.nav_status.isVisible()
    joints = [window.joint_panel.table.cell_text(r, "joint") for r in range(6)]
    assert joints == list(load_ur_profile("ur5e").joint_names)


def test_a_whole_pose_goal_typed_in_the_arm_dock_turns_the_tool_there(
    ur_console: MainWindow, ur_sim: UrSimulator, qtbot: QtBot
) -> None:
    window = ur_console
    panel = window.arm_panel
    assert panel is not None
    assert list(panel.goal_boxes) == ["x", "y", "z", "roll", "pitch", "yaw"]
    arm = window.model.arm
    assert arm is not None
    qtbot.waitUntil(lambda: arm.tool_matrix() is not None, timeout=DEADLINE_MS)
    panel.fill_from_tool()
    start = panel.goal_pose()
    assert isinstance(start, np.ndarray)
    # 50 mm sideways, 80 mm down, the tool turned 25° about the base's z and tilted 10°.
    roll, pitch, yaw = rpy_of(start)
    goal = pose_from_rpy(
        start[:3, 3] + (0.0, 0.05, -0.08), (roll + math.radians(10), pitch, yaw + math.radians(25))
    )
    panel.set_goal_boxes(goal)
    typed = panel.goal_pose()  # as the boxes show it: mm and tenths of a degree
    assert isinstance(typed, np.ndarray)
    panel.accept()
    assert "moving to x" in window.event_log.item(window.event_log.count() - 1).text()
    kinematics = arm.kinematics

    def there(state: UrSimSnapshot) -> bool:
        reached = kinematics.tool_matrix(np.array(state.q))
        return (
            not any(state.qd)
            and float(np.linalg.norm(reached[:3, 3] - typed[:3, 3])) < 0.001
            and angle_between(reached, typed) < math.radians(0.2)
        )

    try:
        qtbot.waitUntil(lambda: there(ur_sim.snapshot()), timeout=4 * DEADLINE_MS)
    except AssertionError:
        reached = kinematics.tool_matrix(np.array(ur_sim.snapshot().q))
        raise AssertionError(
            f"the UR simulator's tool0: {describe_pose(reached)}; typed {describe_pose(typed)}"
        ) from None


def test_cartesian_keys_turn_the_tool_in_place_on_the_ur_simulator(
    ur_console: MainWindow, ur_sim: UrSimulator, qtbot: QtBot
) -> None:
    window = ur_console
    arm = window.model.arm
    assert arm is not None
    qtbot.waitUntil(lambda: arm.tool_matrix() is not None, timeout=DEADLINE_MS)
    kinematics = arm.kinematics
    before = kinematics.tool_matrix(np.array(ur_sim.snapshot().q))
    window.activateWindow()
    window.velocity_panel.setFocus()
    QTest.keyClick(window, Qt.Key.Key_C)  # Cartesian mode
    QTest.keyClick(window, Qt.Key.Key_V)  # the tool frame
    assert arm.cartesian
    assert arm.frame == "tool"
    QTest.keyPress(window, Qt.Key.Key_Q)  # yaw +: about tool0's own z
    wait_sim(
        qtbot,
        ur_sim,
        lambda s: angle_between(before, kinematics.tool_matrix(np.array(s.q))) > 0.2,
        "the tool turned by 0.2 rad",
    )
    QTest.keyRelease(window, Qt.Key.Key_Q)
    wait_sim(qtbot, ur_sim, lambda s: not any(s.qd), "at rest after the release")
    after = kinematics.tool_matrix(np.array(ur_sim.snapshot().q))
    assert float(np.linalg.norm(after[:3, 3] - before[:3, 3])) < 0.002  # it stayed in place
    assert float(after[:3, 2] @ before[:3, 2]) > math.cos(math.radians(1.0))  # about its z


def test_the_status_bar_counts_the_reconnection_attempts_of_a_lost_ur(
    ur_console: MainWindow, ur_sim: UrSimulator, qtbot: QtBot
) -> None:
    window = ur_console
    assert window.link_status.age_label.text().startswith("telemetry")
    ur_sim.stop()  # the controller goes away: its ports refuse from now on
    qtbot.waitUntil(lambda: window.link_status.state == LinkState.LOST, timeout=DEADLINE_MS)
    text = window.link_status.age_label.text

    def failures() -> int:
        # Snapshots come twice a second: the count may pass 2 between two of them.
        found = re.match(r"reconnecting · (\d+) attempts failed · next in \d+\.\d s$", text())
        return int(found.group(1)) if found else 0

    qtbot.waitUntil(lambda: failures() >= 2, timeout=4 * DEADLINE_MS)
    assert window.link_status.state_label.text() == "LINK LOST"


def test_the_engineer_keeps_its_own_key_map(profile: RobotProfile, arm: UrArmProfile) -> None:
    assert load_key_map(profile).hold["Y"] == HoldBinding("shoulder", 1)
    assert load_key_map(ur_robot_profile(arm)).hold["Y"] == HoldBinding("shoulder_lift_joint", 1)


def test_a_sigterm_while_the_console_starts_quits_it_in_order(tmp_path: Path) -> None:
    # The signal comes before the window exists (right after the priority line): the console
    # notes it, builds the window, quits at the event loop's first turn and sends zeros last
    # (a CI run once killed it with Python's default SIGTERM while the link was starting).
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "PYTHONPATH": str(ROOT)}
    with subprocess.Popen(
        [
            *(sys.executable, "-m", "ocu", "--profile", "ur5e"),
            *("--config-dir", str(tmp_path), "--no-gamepad"),
        ],
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    ) as console:
        assert console.stderr is not None
        first = console.stderr.readline()
        assert "scheduling priority" in first, first
        console.send_signal(signal.SIGTERM)
        _, rest = console.communicate(timeout=120)
    assert console.returncode == 0, first + rest
    assert "SIGTERM received, quitting" in rest
    assert "link stopped (zeros sent last)" in rest


@pytest.mark.parametrize(
    "core", [["--in-process"], []], ids=["in-process", "core-process (the default)"]
)
def test_ocu_profile_ur5e_opens_the_console_on_the_ur_simulator(
    tmp_path: Path, core: list[str]
) -> None:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "PYTHONPATH": str(ROOT)}
    # Until it says it is connected (however long a loaded machine takes), then SIGTERM: it
    # quits with zeros last.
    with subprocess.Popen(
        [
            *(sys.executable, "-m", "ocu", "--profile", "ur5e"),
            *("--config-dir", str(tmp_path), "--no-gamepad", *core),
        ],
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    ) as console:
        assert console.stderr is not None
        lines: list[str] = []
        deadline = time.monotonic() + 120.0
        while not any("UR link connected: UR controller 5.10.0 at 127.0.0.1" in x for x in lines):
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
    refused = subprocess.run(
        [sys.executable, "-m", "ocu", "--profile", "ur5e", "--sim-arg=--latency-ms=50"],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
        check=False,
    )
    assert refused.returncode == 2
    assert "--sim-arg is not available for a UR arm yet" in refused.stderr


def test_the_controllers_own_stop_is_shown_and_nothing_resumes_after_it(
    ur_console: MainWindow, ur_sim: UrSimulator, qtbot: QtBot
) -> None:
    window = ur_console
    indicator = window.robot_mode
    qtbot.waitUntil(indicator.isVisible, timeout=DEADLINE_MS)
    assert indicator.text() == "RUNNING · NORMAL"
    assert indicator.mode_style == "moving"
    window.activateWindow()
    window.velocity_panel.setFocus()
    QTest.keyPress(window, Qt.Key.Key_U)  # elbow_joint +, held through the stop
    wait_sim(qtbot, ur_sim, lambda s: s.qd[2] > 0.0, "the elbow moving")
    ur_sim.emergency_stop(True)  # the robot's own red button
    qtbot.waitUntil(lambda: indicator.text() == "EMERGENCY STOP", timeout=DEADLINE_MS)
    assert indicator.mode_style == "refused"
    qtbot.waitUntil(lambda: not window.model.is_moving, timeout=DEADLINE_MS)
    ur_sim.emergency_stop(False)
    qtbot.waitUntil(lambda: indicator.mode_style == "moving", timeout=DEADLINE_MS)
    # The key is still held: the arm stays at rest until the operator acts again.
    accepted = ur_sim.snapshot().accepted
    wait_sim(qtbot, ur_sim, lambda s: s.accepted >= accepted + 25, "25 more commands")
    assert all(v == 0.0 for v in ur_sim.snapshot().qd)
    QTest.keyRelease(window, Qt.Key.Key_U)
