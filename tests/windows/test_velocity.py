"""Velocity and max-velocity windows over the real link to the real simulator."""

from __future__ import annotations

import pytest
from PySide6.QtCore import Qt
from PySide6.QtTest import QTest
from pytestqt.qtbot import QtBot

from ocu.console.model import Source
from ocu.profile import RobotProfile
from ocu.records import LinkState
from ocu.sim.simulator import RobotSimulator
from ocu.widgets.number_box import NumberError, parse_number
from ocu.widgets.value_slider import STEPS
from ocu.windows.main_window import MainWindow
from tests.windows.console_fixtures import DEADLINE_MS, drive_axis, is_zero, wait_sim, wait_zeros


def type_into(qtbot: QtBot, box: object, text: str) -> None:
    from ocu.widgets.number_box import NumberBox

    assert isinstance(box, NumberBox)
    box.setFocus()
    box.selectAll()
    QTest.keyClick(box, Qt.Key.Key_Backspace)
    QTest.keyClicks(box, text)


def test_moving_a_slider_moves_the_joint_at_once(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    slider = console.velocity_panel.sliders["shoulder"]
    slider.setValue(STEPS // 2)
    half = console.model.max_velocity("shoulder") / 2
    state = wait_sim(qtbot, sim, lambda s: s.velocities["shoulder"] > 0, "shoulder moving")
    assert state.commanded_velocities["shoulder"] == pytest.approx(half, abs=1e-4)
    assert console.velocity_panel.boxes["shoulder"].text() == f"{half:.3f}"
    assert console.velocity_panel.source_labels["shoulder"].text() == "slider"
    slider.setValue(0)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped with the slider at zero")


def test_accept_applies_typed_values_together(
    console: MainWindow, sim: RobotSimulator, profile: RobotProfile, qtbot: QtBot
) -> None:
    panel = console.velocity_panel
    type_into(qtbot, panel.boxes["waist"], "0,25")  # a comma decimal mark
    type_into(qtbot, panel.boxes["neck"], "-0.1")
    assert console.model.velocities() == {}  # typing alone sends nothing
    assert all(is_zero(r) for r in sim.received_commands())
    QTest.mouseClick(panel.accept_button, Qt.MouseButton.LeftButton)
    state = wait_sim(
        qtbot, sim, lambda s: s.velocities["waist"] > 0 and s.velocities["neck"] < 0, "both moving"
    )
    assert state.commanded_velocities["waist"] == pytest.approx(0.25, abs=1e-4)
    assert state.commanded_velocities["neck"] == pytest.approx(-0.1, abs=1e-4)
    # Together: no RCP carried one of them without the other.
    moving = [r for r in sim.received_commands() if not is_zero(r)]
    assert all(
        drive_axis(profile, r, "waist") != 0 and drive_axis(profile, r, "neck") != 0 for r in moving
    )
    assert console.velocity_panel.sliders["waist"].value() == round(
        0.25 / console.model.max_velocity("waist") * STEPS
    )


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("abc", "not a number"),
        ("nan", "not a number"),
        ("inf", "not a number"),
        ("1e999", "too large"),
        ("0.9", "outside"),
        ("0,1,2", "not a number"),
        ("", "empty"),
        ("-", "not a number"),
    ],
)
def test_bad_input_is_refused_with_the_reason_and_nothing_is_sent(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot, text: str, reason: str
) -> None:
    panel = console.velocity_panel
    type_into(qtbot, panel.boxes["elbow"], "0.1")  # a good value next to the bad one
    box = panel.boxes["waist"]
    type_into(qtbot, box, text)
    QTest.keyClick(box, Qt.Key.Key_Return)
    assert reason in panel.message_label.text()
    assert reason in box.error
    assert "Not applied" in panel.message_label.text()
    assert console.model.velocities() == {}
    assert all(is_zero(r) for r in sim.received_commands())


def test_number_parsing_is_locale_proof() -> None:
    assert parse_number("0,5", -1, 1) == 0.5
    assert parse_number(" 0.5 ", -1, 1) == 0.5
    assert parse_number("−0,25", -1, 1) == -0.25  # a typographic minus
    assert parse_number(".5", -1, 1) == 0.5
    assert parse_number("5e-1", -1, 1) == 0.5
    with pytest.raises(NumberError, match=r"outside \[-1, 1\] m/s"):
        parse_number("2", -1, 1, "m/s")
    with pytest.raises(NumberError, match="not a number"):
        parse_number("1 000", -1000, 1000)


def test_max_velocity_bounds_sliders_and_hotkeys(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    max_panel = console.max_panel
    type_into(qtbot, max_panel.boxes["waist"], "0,2")
    QTest.mouseClick(max_panel.accept_button, Qt.MouseButton.LeftButton)
    assert console.model.max_velocity("waist") == 0.2
    assert console.model.hotkey_speed("waist") == 0.2
    slider = console.velocity_panel.sliders["waist"]
    slider.setValue(slider.maximum())
    state = wait_sim(qtbot, sim, lambda s: s.velocities["waist"] > 0, "waist moving")
    assert state.commanded_velocities["waist"] == pytest.approx(0.2, abs=1e-4)
    slider.setValue(0)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped")
    QTest.keyPress(console, Qt.Key.Key_E)
    state = wait_sim(qtbot, sim, lambda s: s.velocities["waist"] < 0, "waist moving on E")
    assert state.commanded_velocities["waist"] == pytest.approx(-0.2, abs=1e-4)
    QTest.keyRelease(console, Qt.Key.Key_E)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped")
    # The max slider: never above the profile's hard maximum.
    max_slider = max_panel.sliders["waist"]
    max_slider.setValue(max_slider.maximum())
    hard_max = console.profile.channels["waist"].hard_max
    assert console.model.max_velocity("waist") == hard_max
    assert console.velocity_panel.boxes["waist"].high == hard_max


def test_hotkey_speed_is_settable_below_the_maximum(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    box = console.max_panel.hotkey_boxes["neck"]
    type_into(qtbot, box, "0.1")
    QTest.keyClick(box, Qt.Key.Key_Return)
    assert console.model.hotkey_speed("neck") == 0.1
    console.model.set_max_velocity("neck", 0.05)
    assert box.text() == "0.050"
    type_into(qtbot, box, "0.3")
    QTest.keyClick(box, Qt.Key.Key_Return)
    assert "outside [0, 0.05]" in console.max_panel.message_label.text()
    # A new maximum and a hotkey speed above it, typed together: refused, nothing applied.
    type_into(qtbot, console.max_panel.hotkey_boxes["waist"], "0.4")
    type_into(qtbot, console.max_panel.boxes["waist"], "0.2")
    QTest.keyClick(console.max_panel.boxes["waist"], Qt.Key.Key_Return)
    assert "above the maximum 0.2" in console.max_panel.message_label.text()
    assert console.model.max_velocity("waist") == console.profile.channels["waist"].default_max


def test_switches_torch_and_stop_all(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    panel = console.velocity_panel
    QTest.mouseClick(panel.switch_buttons["flippers"][1], Qt.MouseButton.LeftButton)
    QTest.mouseClick(panel.switch_buttons["gripper"][1], Qt.MouseButton.LeftButton)
    panel.torch_box.setChecked(True)
    state = wait_sim(
        qtbot,
        sim,
        lambda s: s.velocities["flippers"] > 0 and s.velocities["gripper"] > 0 and s.torch,
        "flippers up, gripper opening, torch on",
    )
    assert console.model.channel("flippers").source is Source.SWITCH
    QTest.mouseClick(panel.stop_button, Qt.MouseButton.LeftButton)
    state = wait_sim(qtbot, sim, lambda s: s.all_stopped, "StopAll")
    assert state.torch  # the headlight is not motion
    assert panel.switch_buttons["flippers"][0].isChecked()
    assert console.model.estopped


def test_disconnect_sends_zeros_last_and_connect_comes_back(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    panel = console.velocity_panel
    panel.sliders["elbow"].setValue(STEPS // 2)
    wait_sim(qtbot, sim, lambda s: s.velocities["elbow"] > 0, "elbow moving")
    QTest.mouseClick(panel.connect_button, Qt.MouseButton.LeftButton)
    assert console.link is None
    assert panel.connect_button.text() == "Connect"
    assert console.link_status.state_label.text() == "DISCONNECTED"
    state = wait_zeros(qtbot, sim, "stopped on disconnect", more=0)
    assert state.rcp_count == len(sim.received_commands())
    QTest.mouseClick(panel.connect_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: console.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS)
    assert console.model.velocities() == {}


def assert_nothing_moves(sim: RobotSimulator, qtbot: QtBot, what: str) -> None:
    """Two more periodic RCPs arrive and no RCP so far commanded motion."""
    mark = len(sim.received_commands())
    wait_sim(qtbot, sim, lambda s: s.rcp_count >= mark + 2, "two more RCPs")
    moving = [r for r in sim.received_commands() if not is_zero(r)]
    assert not moving, f"{what}: {len(moving)} RCPs commanded motion"


def test_a_stop_when_latched_still_clears_every_typed_box(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    velocity, targets, maxima = console.velocity_panel, console.joint_panel, console.max_panel
    QTest.keyClick(console, Qt.Key.Key_Space)
    assert console.model.estopped  # latched: the stops below change nothing in the latch
    for stop in ("Space", "StopAll"):
        type_into(qtbot, velocity.boxes["drive_linear"], "0.25")
        type_into(qtbot, targets.boxes["shoulder"], "30")
        type_into(qtbot, maxima.boxes["waist"], "0.1")
        type_into(qtbot, maxima.hotkey_boxes["neck"], "0.05")
        if stop == "Space":
            QTest.keyClick(maxima.hotkey_boxes["neck"], Qt.Key.Key_Space)
        else:
            QTest.mouseClick(velocity.stop_button, Qt.MouseButton.LeftButton)
        for box in (
            velocity.boxes["drive_linear"],
            targets.boxes["shoulder"],
            maxima.boxes["waist"],
            maxima.hotkey_boxes["neck"],
        ):
            QTest.keyClick(box, Qt.Key.Key_Return)  # Enter applies whatever is still typed
        assert_nothing_moves(sim, qtbot, f"Enter after {stop}")
        assert velocity.boxes["drive_linear"].text() == "0.000", stop
        assert targets.boxes["shoulder"].text() == "", stop
        assert maxima.boxes["waist"].text() == f"{console.model.max_velocity('waist'):.3f}"
        assert maxima.hotkey_boxes["neck"].text() == f"{console.model.hotkey_speed('neck'):.3f}"
        assert console.model.targets == {}, stop
        assert console.model.velocities() == {}, stop
        assert console.model.max_velocity("waist") == console.profile.channels["waist"].default_max
        assert console.model.hotkey_speed("neck") == console.model.max_velocity("neck")


SLIDER_KEYS = (
    Qt.Key.Key_Home,
    Qt.Key.Key_End,
    Qt.Key.Key_PageUp,
    Qt.Key.Key_PageDown,
    Qt.Key.Key_Left,
    Qt.Key.Key_Right,
    Qt.Key.Key_Up,
    Qt.Key.Key_Down,
)


def test_sliders_and_switches_take_no_keys(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    panel = console.velocity_panel
    drive = panel.sliders["drive_linear"]
    stop_switch = panel.switch_buttons["flippers"][0]
    QTest.mouseClick(drive, Qt.MouseButton.LeftButton, pos=drive.rect().center())  # zero
    QTest.mouseClick(stop_switch, Qt.MouseButton.LeftButton)
    clicked_focus = drive.hasFocus() or stop_switch.hasFocus()
    # Belt and braces: given the focus anyway, they still ignore the keys.
    for widget, keys in (
        (drive, SLIDER_KEYS),
        (panel.sliders["waist"], SLIDER_KEYS),
        (stop_switch, SLIDER_KEYS[4:]),  # the arrows would click its neighbour
        (console.max_panel.sliders["drive_linear"], SLIDER_KEYS),  # End: the hard maximum
    ):
        widget.setFocus()
        for key in keys:
            QTest.keyClick(widget, key)
    assert_nothing_moves(sim, qtbot, "keys at sliders and switches")
    assert all(s.value() == 0 for s in panel.sliders.values())
    default_max = console.profile.channels["drive_linear"].default_max
    assert console.model.max_velocity("drive_linear") == default_max
    assert stop_switch.isChecked()
    assert not clicked_focus  # a click gives neither the focus
    assert all(s.focusPolicy() == Qt.FocusPolicy.NoFocus for s in panel.sliders.values())
