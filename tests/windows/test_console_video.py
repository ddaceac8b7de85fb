"""The video dock in the console: four streams from an extended robot, the headlight the robot
reports next to the Torch box, and a camera selection that survives the operator's commands."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from PySide6.QtCore import Qt
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.profile import RobotProfile
from ocu.protocol.mapping import CommandMapper
from ocu.records import LinkState
from ocu.sim.simulator import RobotSimulator
from ocu.widgets.video import LIVE
from ocu.widgets.video_status import NOT_REPORTED
from tests.windows.console_fixtures import DEADLINE_MS, ConsoleFactory, drive_axis, wait_sim

CAMERAS = 4


@pytest.fixture
def extended_sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """A simulator that speaks the protocol extension: four cameras and a status packet."""
    simulator = RobotSimulator(
        profile, extended=True, telemetry_hz=5.0, video_fps=0.0, battery_percent=80.0, seed=3
    )
    simulator.start()
    yield simulator
    simulator.stop()


def test_four_streams_arrive_in_the_console_and_the_headlight_is_the_robots(
    make_console: ConsoleFactory, extended_sim: RobotSimulator, qtbot: QtBot
) -> None:
    console = make_console(extended_sim, extension=True)
    panel = console.video_panel
    assert console.video_dock.widget() is panel
    assert panel.link is console.link
    qtbot.waitUntil(lambda: panel.extension_active, timeout=DEADLINE_MS)
    for camera in range(CAMERAS):  # lighter streams for the test machine
        panel.set_stream_request(camera, 320, 240, 10)
    view = panel.view
    qtbot.waitUntil(
        lambda: all(view.stats(k).shown >= 3 for k in range(CAMERAS)), timeout=DEADLINE_MS
    )
    assert view.grid
    assert all(view.signal_state(k) == LIVE for k in range(CAMERAS))

    headlight = console.velocity_panel.headlight
    qtbot.waitUntil(lambda: headlight.text() == "Headlight: off", timeout=DEADLINE_MS)
    assert panel.battery.charge_percent is not None  # battery and roll/pitch are shown too
    assert panel.attitude.roll_rad is not None
    # The indicator follows what the robot reports, not the checkbox.
    console.velocity_panel.torch_box.setChecked(True)
    qtbot.waitUntil(lambda: headlight.text() == "Headlight: ON", timeout=DEADLINE_MS)
    assert extended_sim.state().torch
    console.velocity_panel.torch_box.setChecked(False)
    qtbot.waitUntil(lambda: headlight.text() == "Headlight: off", timeout=DEADLINE_MS)

    # The stream sizes and rates chosen are remembered: the next console asks for them.
    panel.set_stream_request(2, 1280, 720, 15)
    console.shutdown()
    again = make_console(extended_sim, extension=True)
    request = again.model.stream_request[2]
    assert (request.width_px, request.height_px, request.fps) == (1280, 720, 15)
    assert again.model.stream_request[0].fps == 10
    assert again.video_panel.controls.size_box.currentData() is not None


def test_headlight_not_reported_by_a_vendor_robot(
    make_console: ConsoleFactory, sim: RobotSimulator, qtbot: QtBot
) -> None:
    console = make_console(sim, extension=True)
    headlight = console.velocity_panel.headlight
    console.velocity_panel.torch_box.setChecked(True)
    wait_sim(qtbot, sim, lambda s: s.torch, "torch on")
    # The hellos go unanswered (counted as foreign by the simulator): nothing is reported.
    wait_sim(qtbot, sim, lambda s: s.foreign_count > 0, "the extension probed")
    assert not console.video_panel.extension_active
    assert headlight.text() == f"Headlight: {NOT_REPORTED}"
    assert headlight.headlight_on is None


def test_a_camera_switch_survives_hotkeys(
    make_console: ConsoleFactory, sim: RobotSimulator, qtbot: QtBot, profile: RobotProfile
) -> None:
    console = make_console(sim, extension=True)
    console.video_panel.select_camera(2)
    wait_sim(qtbot, sim, lambda s: s.camera == 2, "camera 2 selected")
    switched_at = sim.state().time_s

    QTest.keyPress(console, Qt.Key.Key_W)
    state = wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0, "driving forward")
    assert state.camera == 2
    QTest.keyRelease(console, Qt.Key.Key_W)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped after the release")

    mapper = CommandMapper(profile)
    after = [r for r in sim.received_commands() if r.time_s > switched_at]
    assert any(drive_axis(profile, r, "drive_linear") > 0 for r in after)
    assert {mapper.to_command(r.packet).camera for r in after} == {2}
    assert console.link is not None
    assert console.link.link.command.camera == 2


def test_stream_settings_text_is_checked() -> None:
    from ocu.windows.main_window import format_stream_setting, parse_stream_setting

    request = parse_stream_setting("3:1280x720@30")
    assert (request.camera, request.width_px, request.height_px, request.fps) == (3, 1280, 720, 30)
    assert parse_stream_setting(format_stream_setting(request)) == request
    for bad in ("", "3:1280x720", "x:1x1@1", "3:0x720@30", "300:640x480@30"):
        with pytest.raises(ValueError, match="CAMERA:WIDTHxHEIGHT@FPS"):
            parse_stream_setting(bad)


def test_the_operators_single_view_survives_a_lost_link(
    make_console: ConsoleFactory, extended_sim: RobotSimulator, qtbot: QtBot
) -> None:
    console = make_console(extended_sim, extension=True, link_lost_after_s=1.0)
    panel = console.video_panel
    qtbot.waitUntil(lambda: panel.extension_active, timeout=DEADLINE_MS)
    assert panel.view.grid  # the extension's four cameras at once, to begin with
    panel.controls.single_button.click()  # the operator wants one camera
    assert not panel.view.grid
    changes: list[bool] = []
    console.model.robot.events.extension_changed.connect(lambda on, _why: changes.append(on))
    extended_sim.cut_link()
    qtbot.waitUntil(lambda: console.link_status.state == LinkState.LOST, timeout=DEADLINE_MS)
    extended_sim.restore_link()
    # The model's events reach this (GUI) thread after the control thread changed its state.
    qtbot.waitUntil(
        lambda: (
            console.link_status.state == LinkState.CONNECTED
            and panel.extension_active
            and changes[-1:] == [True]  # the extension came back (the old grid trigger)
        ),
        timeout=DEADLINE_MS,
    )
    assert not panel.view.grid
    assert panel.controls.single_button.isChecked()
