"""The console's control thread: control goes on while the GUI thread runs no event at all."""

from __future__ import annotations

import math
import time

from pytestqt.qtbot import QtBot

from ocu.sim.simulator import RobotSimulator
from ocu.windows.main_window import MainWindow
from tests.windows.console_fixtures import DEADLINE_MS, ConsoleFactory, wait_sim

STEP_DEG = 20.0
BUSY_LIMIT_S = 6.0


def test_a_position_move_ends_at_its_target_while_the_gui_runs_no_event(
    qtbot: QtBot, make_console: ConsoleFactory, sim: RobotSimulator
) -> None:
    # The GUI thread busy for seconds (a heavy paint, say) but alive: it says so, yet runs no
    # Qt event - no timer, no signal. The control thread alone must take the joint to its
    # target and stop it there. (On the GUI thread the control tick would not run: the joint
    # would go on at its last speed until the link's watchdog zeroed it, short of or past
    # the target.)
    console: MainWindow = make_console(sim)
    qtbot.waitUntil(lambda: console.model.robot.last_telemetry_at is not None, timeout=DEADLINE_MS)
    start = sim.state().joints_rad["neck"]
    target = start + math.radians(STEP_DEG)
    console.model.set_target("neck", target)
    wait_sim(qtbot, sim, lambda s: s.velocities["neck"] > 0.0, "the neck moving")
    cycles = console.core.timing().cycles
    deadline = time.monotonic() + BUSY_LIMIT_S
    stopped = False
    while time.monotonic() < deadline:
        time.sleep(0.05)  # busy: no event loop here
        console.core.gui_alive()
        state = sim.state()
        if state.velocities["neck"] == 0.0 and state.commanded_velocities.get("neck", 0.0) == 0.0:
            stopped = True
            break
    assert stopped, "the neck did not stop while the GUI thread ran no event"
    assert console.core.timing().cycles > cycles
    error_deg = math.degrees(sim.state().joints_rad["neck"] - target)
    assert abs(error_deg) <= 1.0, f"stopped {error_deg:+.2f} deg from its target"
    # The views hear of it when the GUI thread runs again.
    qtbot.waitUntil(lambda: not console.model.targets, timeout=DEADLINE_MS)
