"""The Link dock in the console, on the real simulator: graphs from real telemetry, the command
rate it sets on the wire, and the rate remembered across a restart of the window."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import pytest
from PySide6.QtCore import QSettings, Qt
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.profile import RobotProfile
from ocu.records import LinkStats
from ocu.sim.faults import FaultConfig
from ocu.sim.simulator import RobotSimulator
from ocu.widgets.link_graphs import RATE_KEY, UPLINK_UNMEASURABLE_TITLE, LinkGraphsPanel
from ocu.windows.main_window import MainWindow
from tests.windows.console_fixtures import DEADLINE_MS, ConsoleFactory

# RCPs counted over this long to tell the rate on the wire.
COUNT_WINDOW_S = 2.0


@pytest.fixture
def lossy_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """The simulator behind a radio that loses a fifth of the datagrams each way."""
    sim = RobotSimulator(
        profile, telemetry_hz=10.0, video_fps=0.0, faults=FaultConfig(loss=0.2), seed=11
    )
    sim.start()
    yield sim
    sim.stop()


def show_link_dock(window: MainWindow) -> LinkGraphsPanel:
    """The Link dock brought to the front (it shares its place with other docks)."""
    window.link_dock.show()
    window.link_dock.raise_()
    return window.link_graphs


def rcp_rate_on_the_wire(qtbot: QtBot, sim: RobotSimulator) -> float:
    """RCPs per second the simulator received over COUNT_WINDOW_S, from now on."""
    start = len(sim.received_commands())
    first = sim.received_commands()[-1].time_s if start else 0.0

    def window_passed() -> bool:
        received = sim.received_commands()
        return len(received) > start and received[-1].time_s - first >= COUNT_WINDOW_S

    qtbot.waitUntil(window_passed, timeout=DEADLINE_MS)
    received = [r for r in sim.received_commands()[start:] if r.time_s - first <= COUNT_WINDOW_S]
    return len(received) / COUNT_WINDOW_S


def test_the_graphs_hold_the_lossy_links_figures_and_mark_an_emergency_stop(
    qtbot: QtBot, make_console: ConsoleFactory, lossy_sim: RobotSimulator
) -> None:
    window = make_console(lossy_sim)
    panel = show_link_dock(window)

    def drawn() -> bool:
        return (
            panel.curve_points("command_rate_hz") >= 3
            and panel.curve_points("telemetry_rate_hz") >= 3
            and panel.curve_points("downlink_loss") >= 1
        )

    qtbot.waitUntil(drawn, timeout=DEADLINE_MS * 2)
    assert panel.redraws > 0
    # Telemetry at 10 Hz through 20 % loss: something arrives, not everything.
    stats = panel.history.latest()
    assert stats is not None
    assert 0.0 < stats.telemetry_rate_hz < 10.0
    assert "not measurable" in panel.figures.text()
    QTest.keyClick(window, Qt.Key.Key_Space)
    qtbot.waitUntil(lambda: "E-STOP" in panel.mark_labels(), timeout=DEADLINE_MS)


def test_the_command_rate_set_in_the_dock_reaches_the_wire(
    qtbot: QtBot, make_console: ConsoleFactory, sim: RobotSimulator, profile: RobotProfile
) -> None:
    window = make_console(sim)
    panel = show_link_dock(window)
    assert panel.rate_box.value() == profile.link.send_rate_hz
    before = rcp_rate_on_the_wire(qtbot, sim)
    assert 3.5 <= before <= 6.5
    panel.rate_box.setValue(20)
    qtbot.waitUntil(lambda: window.link is not None and window.link.link.rate_hz == 20.0)
    after = rcp_rate_on_the_wire(qtbot, sim)
    assert 16.0 <= after <= 24.0


def test_the_command_rate_and_window_are_remembered_across_a_restart(
    qtbot: QtBot, make_console: ConsoleFactory, sim: RobotSimulator
) -> None:
    first = make_console(sim)
    show_link_dock(first).rate_box.setValue(12)
    first.link_graphs.window_box.setValue(7)
    first.shutdown()
    assert first.settings.value(RATE_KEY) is not None

    second = make_console(sim)
    panel = show_link_dock(second)
    assert panel.rate_box.value() == 12
    assert panel.window_box.value() == 7
    assert second.link is not None
    assert second.link.link.rate_hz == 12.0
    assert 9.5 <= rcp_rate_on_the_wire(qtbot, sim) <= 14.5


def test_the_commands_lost_curve_replaces_the_statement_when_the_robot_echoes(
    qtbot: QtBot, profile: RobotProfile, settings: QSettings
) -> None:
    panel = LinkGraphsPanel(profile, settings)
    qtbot.addWidget(panel)
    vendor = replace(LinkStats.empty(5.0), rcp_rate_hz=5.0, last_valid_age_s=0.1)
    now = panel.history.clock()
    panel.history.add(vendor, now - 2.0)
    panel.redraw(force=True)
    assert UPLINK_UNMEASURABLE_TITLE in panel.plots["loss"].titleLabel.text
    assert "not measurable" in panel.figures.text()
    assert panel.curve_points("uplink_loss") == 0
    for age_s in (1.0, 0.5, 0.0):
        panel.history.add(replace(vendor, uplink_loss=0.3), now - age_s)
    panel.redraw(force=True)
    assert UPLINK_UNMEASURABLE_TITLE not in panel.plots["loss"].titleLabel.text
    assert "commands lost (OCU → robot)" in panel.plots["loss"].titleLabel.text
    assert "commands lost 30%" in panel.figures.text()
    assert panel.curve_points("uplink_loss") == 3
