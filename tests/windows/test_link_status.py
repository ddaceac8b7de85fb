"""The status bar's link state: what it reports is what it shows, also while the model's
change is still on its way to the GUI thread (the control thread changes the model first)."""

from __future__ import annotations

import threading

from pytestqt.qtbot import QtBot

from ocu.console.events import hand_over
from ocu.console.model import ConsoleModel
from ocu.profile import RobotProfile
from ocu.qt.inbox import gui_inbox
from ocu.records import LinkState
from ocu.widgets.link_status import STATE_TEXT, LinkStatus

DEADLINE_MS = 5000


def test_the_state_reported_is_the_state_shown(qtbot: QtBot, profile: RobotProfile) -> None:
    gui_inbox()  # the GUI thread's dispatcher for handed-over events
    model = ConsoleModel(profile)
    hand_over(model.events, model.robot.events)
    status = LinkStatus(model, "simulator")
    qtbot.addWidget(status)
    model.robot.on_link_state(LinkState.CONNECTED, "packets arrive")
    qtbot.waitUntil(lambda: status.state_label.text() == "CONNECTED", timeout=DEADLINE_MS)
    # The control thread declares LINK LOST; its event has not reached the GUI thread yet.
    worker = threading.Thread(
        target=model.robot.on_link_state, args=(LinkState.LOST, "no packets for 3 s")
    )
    worker.start()
    worker.join()
    assert model.robot.link_state is LinkState.LOST
    assert status.state_label.text() == STATE_TEXT[status.state]  # not LOST before it shows
    qtbot.waitUntil(lambda: status.state is LinkState.LOST, timeout=DEADLINE_MS)
    assert status.state_label.text() == "LINK LOST"
