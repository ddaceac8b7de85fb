"""The console under the field's conditions, against the real simulator: a telemetry flood,
a broken encoder, a slow link (measured delay, predictive display), the turn radius."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest
from PySide6.QtCore import Qt
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.profile import RobotProfile
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator
from ocu.windows.main_window import MainWindow
from tests.windows.console_fixtures import (
    DEADLINE_MS,
    ConsoleFactory,
    drive_axis,
    is_zero,
    wait_sim,
)
from tests.windows.test_velocity import type_into

# A released key must reach the robot as a zero this soon, whatever the telemetry does.
PROMPT_S = 0.2


@pytest.fixture
def flood_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """A robot that sends 500 telemetry packets per second (main stalled at 300)."""
    simulator = RobotSimulator(profile, telemetry_hz=500.0, video_fps=0.0)
    simulator.start()
    yield simulator
    simulator.stop()


def test_a_telemetry_flood_does_not_delay_the_keys(
    make_console: ConsoleFactory, flood_sim: RobotSimulator, qtbot: QtBot
) -> None:
    console = make_console(flood_sim)
    for _ in range(3):
        QTest.keyPress(console, Qt.Key.Key_W)
        wait_sim(qtbot, flood_sim, lambda s: s.velocities["drive_linear"] > 0, "driving")
        count = len(flood_sim.received_commands())
        released = flood_sim.state().time_s
        QTest.keyRelease(console, Qt.Key.Key_W)
        wait_sim(qtbot, flood_sim, lambda s: s.velocities["drive_linear"] == 0, "stopped")
        zeros = [r for r in flood_sim.received_commands()[count:] if is_zero(r)]
        assert zeros
        assert zeros[0].time_s - released < PROMPT_S
    # The views still follow the robot (at their own pace).
    assert console.link_status.last_telemetry_at is not None


def test_a_broken_encoder_is_shown_and_refused(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    sim.set_raw_position("shoulder", 0)
    panel = console.joint_panel
    label = panel.angle_labels["shoulder"]
    qtbot.waitUntil(lambda: label.text() == "implausible", timeout=DEADLINE_MS)
    assert "0x00000000" in label.toolTip()
    row = next(
        r for r in range(panel.table.rowCount()) if panel.table.cell_text(r, "joint") == "shoulder"
    )
    assert panel.table.cell_text(row, "angle °").startswith("⚠")
    assert console.model_view.fault_joints == {"shoulder"}
    type_into(qtbot, panel.boxes["shoulder"], "60")
    QTest.mouseClick(panel.accept_button, Qt.MouseButton.LeftButton)
    assert "implausible" in panel.message_label.text()
    assert console.model.targets == {}
    assert all(is_zero(r) for r in sim.received_commands())
    sim.set_raw_position("shoulder", None)
    qtbot.waitUntil(lambda: label.text() != "implausible", timeout=DEADLINE_MS)
    assert console.model_view.fault_joints == frozenset()


def test_the_turn_radius_is_kept(
    console: MainWindow, sim: RobotSimulator, profile: RobotProfile, qtbot: QtBot
) -> None:
    panel = console.velocity_panel
    type_into(qtbot, panel.boxes["drive_linear"], "0.1")
    type_into(qtbot, panel.boxes["drive_turn"], "0.05")
    QTest.mouseClick(panel.accept_button, Qt.MouseButton.LeftButton)
    wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0, "driving an arc")
    rcp = next(r for r in sim.received_commands() if not is_zero(r))
    linear = (
        drive_axis(profile, rcp, "drive_linear") / profile.channels["drive_linear"].axis_per_unit
    )
    turn = drive_axis(profile, rcp, "drive_turn") / profile.channels["drive_turn"].axis_per_unit
    # Lifted to the servos' starting speed by one factor: (0.2, 0.1), not (0.2, 0.2).
    assert linear == pytest.approx(0.2, abs=1e-3)
    assert turn == pytest.approx(0.1, abs=1e-3)
    assert panel.boxes["drive_linear"].text() == "0.200"
    QTest.keyClick(console, Qt.Key.Key_Space)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped")


def shown_delay_ms(console: MainWindow) -> float:
    """The delay the status bar shows (NaN while it shows none)."""
    text = console.link_status.loss_label.text()
    _, _, rest = text.partition("delay ")
    number = rest.split(" ms")[0]
    return float(number) if number.isdigit() else math.nan


def test_a_slow_link_shows_its_delay_and_the_predicted_arm(
    make_console: ConsoleFactory, profile: RobotProfile, qtbot: QtBot
) -> None:
    sim = RobotSimulator(profile, telemetry_hz=5.0, video_fps=0.0,
                         faults=FaultConfig(latency_ms=150.0))  # fmt: skip
    sim.start()
    try:
        console = make_console(sim)
        view = console.model_view
        QTest.keyPress(console, Qt.Key.Key_Y)  # shoulder up
        # Between readings the predicted shoulder runs ahead of the last reading.
        qtbot.waitUntil(
            lambda: (
                view.reading is not None
                and view.live.position("shoulder") - view.reading.position("shoulder")
                > math.radians(2.0)
            ),
            timeout=DEADLINE_MS,
        )
        # Held until a reading echoes the command: a press shorter than a telemetry period
        # (0.2 s here) may never be echoed, and then the command's edges tell no delay.
        robot = console.model.robot
        qtbot.waitUntil(
            lambda: "shoulder" in robot.readings and robot.readings["shoulder"].speed_rad_s > 0,
            timeout=DEADLINE_MS,
        )
        QTest.keyRelease(console, Qt.Key.Key_Y)
        # The edges of the command measure the round trip: 300 ms here.
        qtbot.waitUntil(lambda: 200 <= shown_delay_ms(console) <= 400, timeout=DEADLINE_MS)
        wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped")
        truth = sim.state().joints_rad["shoulder"]
        # Once the readings catch up, the drawn arm is where the robot is.
        qtbot.waitUntil(
            lambda: (
                view.reading is not None
                and abs(view.reading.position("shoulder") - truth) < math.radians(0.2)
            ),
            timeout=DEADLINE_MS,
        )
        # The predicted pose follows: its offset is filtered, so it may take a few readings.
        qtbot.waitUntil(
            lambda: abs(view.live.position("shoulder") - truth) < math.radians(0.5),
            timeout=DEADLINE_MS,
        )
    finally:
        sim.stop()
