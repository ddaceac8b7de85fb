"""Hotkeys in the console, over the real link to the real simulator."""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
from PySide6.QtCore import QEvent, Qt
from PySide6.QtGui import QKeyEvent
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QApplication
from pytestqt.qtbot import QtBot

from ocu.profile import RobotProfile
from ocu.records import JointReading, TelemetryFrame
from ocu.sim.simulator import RobotSimulator
from ocu.windows.key_filter import key_from_qt, key_name
from ocu.windows.main_window import MainWindow
from tests.test_hotkeys import TABLE_4
from tests.windows.console_fixtures import (
    DEADLINE_MS,
    drive_axis,
    is_zero,
    mid_range_joints,
    wait_sim,
    wait_zeros,
)

NO_MOD = Qt.KeyboardModifier.NoModifier
XCB_W = 17 + 8  # X11 key code of the W position: evdev code + 8
T0 = 1_000_000  # an X server time (ms) for synthetic events
X_DELAY_MS = 660  # X11's default auto-repeat delay and interval (25 Hz)
X_INTERVAL_MS = 40


class Telemetry:
    """The latest telemetry the console received (the link thread appends)."""

    def __init__(self, window: MainWindow) -> None:
        self.frames: list[TelemetryFrame] = []
        assert window.link is not None
        window.link.telemetry_received.connect(self.frames.append)

    def latest(self) -> dict[str, JointReading]:
        return self.frames[-1].readings if self.frames else {}

    def count(self) -> int:
        return len(self.frames)


def qt_key(name: str) -> Qt.Key:
    return Qt.Key(ord(name))


def send_key(
    window: MainWindow,
    kind: QEvent.Type,
    key: int,
    text: str,
    *,
    auto: bool = False,
    scan_code: int = 0,
    modifiers: Qt.KeyboardModifier = NO_MOD,
    timestamp: int = 0,
) -> None:
    event = QKeyEvent(kind, key, modifiers, scan_code, 0, 0, text, auto)
    event.setTimestamp(timestamp)  # the X server's milliseconds; 0 as QTest's events
    target = QApplication.focusWidget() or window
    QApplication.sendEvent(target, event)


def moving(readings: dict[str, JointReading], channel: str, direction: int) -> bool:
    """Whether telemetry shows the joint (or, for the drive, the tracks) moving that way."""
    if not readings:
        return False
    if channel == "drive_linear":
        left, right = readings["left_track"].speed_rad_s, readings["right_track"].speed_rad_s
        return left * direction > 0 and right * direction > 0
    if channel == "drive_turn":
        left, right = readings["left_track"].speed_rad_s, readings["right_track"].speed_rad_s
        return right * direction > 0 and left * direction < 0
    return readings[channel].speed_rad_s * direction > 0


def still(readings: dict[str, JointReading]) -> bool:
    return bool(readings) and all(r.speed_rad_s == 0.0 for r in readings.values())


@pytest.fixture
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """The simulator with every bounded joint mid-range: each key has room both ways."""
    simulator = RobotSimulator(
        profile, telemetry_hz=10.0, video_fps=0.0, initial_joints=mid_range_joints(profile)
    )
    simulator.start()
    yield simulator
    simulator.stop()


def test_each_hotkey_moves_its_joint_and_stops_on_release(
    console: MainWindow, qtbot: QtBot
) -> None:
    telemetry = Telemetry(console)
    for key, (channel, direction) in TABLE_4.items():
        QTest.keyPress(console, qt_key(key))

        def shows_motion(c: str = channel, d: int = direction) -> bool:
            return moving(telemetry.latest(), c, d)

        qtbot.waitUntil(shows_motion, timeout=DEADLINE_MS)
        QTest.keyRelease(console, qt_key(key))
        qtbot.waitUntil(lambda: still(telemetry.latest()), timeout=DEADLINE_MS)
        assert console.model.velocities() == {}, key


def test_two_keys_at_once(console: MainWindow, sim: RobotSimulator, qtbot: QtBot) -> None:
    QTest.keyPress(console, Qt.Key.Key_Y)
    QTest.keyPress(console, Qt.Key.Key_U)
    state = wait_sim(
        qtbot,
        sim,
        lambda s: s.velocities["shoulder"] > 0 and s.velocities["elbow"] > 0,
        "shoulder and elbow moving together",
    )
    assert state.velocities["shoulder"] == console.model.hotkey_speed("shoulder")
    QTest.keyRelease(console, Qt.Key.Key_Y)
    wait_sim(
        qtbot,
        sim,
        lambda s: s.velocities["shoulder"] == 0 and s.velocities["elbow"] > 0,
        "elbow still moving after the shoulder key went up",
    )
    QTest.keyRelease(console, Qt.Key.Key_U)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "all stopped")


def test_auto_repeat_pairs_are_ignored(
    console: MainWindow, sim: RobotSimulator, profile: RobotProfile, qtbot: QtBot
) -> None:
    send_key(console, QEvent.Type.KeyPress, Qt.Key.Key_W, "w", timestamp=T0)
    wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0, "driving forward")
    mark = len(sim.received_commands())
    for n in range(20):  # what a held key produces on X11: release+press pairs, auto-repeat
        at = T0 + X_DELAY_MS + n * X_INTERVAL_MS  # the pair shares the server's time
        send_key(console, QEvent.Type.KeyRelease, Qt.Key.Key_W, "w", auto=True, timestamp=at)
        send_key(console, QEvent.Type.KeyPress, Qt.Key.Key_W, "w", auto=True, timestamp=at)
    assert console.model.held_keys == frozenset({"W"})
    # Let periodic RCPs arrive: none of them may stop the drive.
    wait_sim(qtbot, sim, lambda s: s.rcp_count >= mark + 2, "two more RCPs")
    assert all(drive_axis(profile, r, "drive_linear") > 0 for r in sim.received_commands()[mark:])
    QTest.keyRelease(console, Qt.Key.Key_W)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped on the real release")


def x_repeat_pairs(window: MainWindow, first_ms: int, count: int) -> int:
    """What X11 sends for a held W: release+press pairs sharing a server time, not flagged
    (Qt 6.11 under Xvfb flags hardly any). Returns the time of the last pair."""
    at = first_ms
    for n in range(count):
        at = first_ms + n * X_INTERVAL_MS
        send_key(window, QEvent.Type.KeyRelease, Qt.Key.Key_W, "w", timestamp=at)
        send_key(window, QEvent.Type.KeyPress, Qt.Key.Key_W, "w", timestamp=at)
    return at


def motion_since(sim: RobotSimulator, index: int) -> list[int]:
    return [i for i, r in enumerate(sim.received_commands()[index:]) if not is_zero(r)]


def no_motion_for_two_rcps(sim: RobotSimulator, qtbot: QtBot, since: int, what: str) -> None:
    wait_sim(qtbot, sim, lambda s: s.rcp_count >= since + 2, "two more RCPs")
    assert not motion_since(sim, since), what


def test_repeats_of_a_key_never_seen_going_down_do_not_move_the_robot(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    # W was pressed in another window; the console gets only its auto-repeats.
    last = x_repeat_pairs(console, T0, 10)
    no_motion_for_two_rcps(sim, qtbot, 0, "W held before the console had the keyboard")
    assert console.model.held_keys == frozenset()
    # Released and pressed again: a real press drives.
    send_key(console, QEvent.Type.KeyRelease, Qt.Key.Key_W, "w", timestamp=last + 15)
    send_key(console, QEvent.Type.KeyPress, Qt.Key.Key_W, "w", timestamp=last + 300)
    wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0, "driving on a new press")
    # Space while W is held: the key's auto-repeat must not start the robot again.
    QTest.keyClick(console, Qt.Key.Key_Space)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped by Space")
    mark = len(sim.received_commands())
    last = x_repeat_pairs(console, last + 300 + X_DELAY_MS, 10)
    no_motion_for_two_rcps(sim, qtbot, mark, "W's auto-repeat after Space")
    assert console.model.estopped
    send_key(console, QEvent.Type.KeyRelease, Qt.Key.Key_W, "w", timestamp=last + 15)


def test_a_press_repeated_sooner_than_any_auto_repeat_is_stopped_at_once(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    # A key held elsewhere, repeated as presses only (XKB detectable auto-repeat, other
    # platforms): the first press looks real, the second comes 40 ms later -- no keyboard
    # repeats that soon, so the first one was a repeat as well.
    send_key(console, QEvent.Type.KeyPress, Qt.Key.Key_W, "w", timestamp=T0)
    send_key(console, QEvent.Type.KeyPress, Qt.Key.Key_W, "w", timestamp=T0 + X_INTERVAL_MS)
    stop_at = time.monotonic()
    # A zero received after the stop: any RCP the link sent before it has arrived too.
    wait_sim(
        qtbot,
        sim,
        lambda _s: any(r.time_s > stop_at and is_zero(r) for r in sim.received_commands()),
        "stopped at the second press",
    )
    assert console.model.held_keys == frozenset()
    mark = len(sim.received_commands())
    for n in range(2, 12):
        at = T0 + n * X_INTERVAL_MS
        send_key(console, QEvent.Type.KeyPress, Qt.Key.Key_W, "w", timestamp=at)
    no_motion_for_two_rcps(sim, qtbot, mark, "further repeats")
    assert console.model.held_keys == frozenset()
    send_key(console, QEvent.Type.KeyRelease, Qt.Key.Key_W, "w", timestamp=T0 + 500)
    send_key(console, QEvent.Type.KeyPress, Qt.Key.Key_W, "w", timestamp=T0 + 800)
    wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0, "driving on a new press")
    send_key(console, QEvent.Type.KeyRelease, Qt.Key.Key_W, "w", timestamp=T0 + 900)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped on release")


def test_keys_work_by_position_on_a_russian_layout(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    assert console.key_filter is not None
    console.key_filter.platform = "xcb"  # offscreen synthesises no scan codes; X11 sends these
    # The key at the W position prints 'ц' on the Russian layout; Qt's key code is 'Ц'.
    send_key(console, QEvent.Type.KeyPress, ord("Ц"), "ц", scan_code=XCB_W)
    wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0, "driving forward on 'ц'")
    send_key(console, QEvent.Type.KeyRelease, ord("Ц"), "ц", scan_code=XCB_W)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped on releasing 'ц'")


def test_key_names_from_scan_codes_and_qt_keys() -> None:
    russian_w = QKeyEvent(QEvent.Type.KeyPress, ord("Ц"), NO_MOD, XCB_W, 0, 0, "ц")
    assert key_name(russian_w, "xcb") == "W"
    windows_w = QKeyEvent(QEvent.Type.KeyPress, ord("Ц"), NO_MOD, 17, 0, 0, "ц")
    assert key_name(windows_w, "windows") == "W"  # Windows reports the set-1 code itself
    no_scan = QKeyEvent(QEvent.Type.KeyPress, Qt.Key.Key_W, NO_MOD, 0, 0, 0, "w")
    assert key_name(no_scan, "xcb") == "W"  # synthetic events: Qt's key code
    assert key_from_qt(Qt.Key.Key_W) == "W"
    assert key_from_qt(Qt.Key.Key_Question) == "Slash"
    assert key_from_qt(Qt.Key.Key_Slash) == "Slash"
    assert key_from_qt(Qt.Key.Key_F1) == "F1"
    assert key_from_qt(Qt.Key.Key_Space) == "Space"
    assert key_from_qt(Qt.Key.Key_Exclam) == "1"
    assert key_from_qt(ord("Ц")) is None


def test_shift_moves_at_the_fine_speed(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    shift = Qt.KeyboardModifier.ShiftModifier
    QTest.keyPress(console, Qt.Key.Key_Q, shift)
    fine = console.model.fine_speed("waist")
    assert fine < console.model.hotkey_speed("waist")
    wait_sim(
        qtbot, sim, lambda s: abs(s.velocities["waist"] - fine) < 1e-3, "waist at the fine speed"
    )
    QTest.keyRelease(console, Qt.Key.Key_Q, shift)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped")


def test_letters_go_to_a_focused_text_box_not_to_the_robot(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    box = console.velocity_panel.boxes["waist"]
    box.setFocus()
    qtbot.waitUntil(box.hasFocus, timeout=DEADLINE_MS)
    box.clear()
    QTest.keyClicks(box, "wasd")
    assert box.text() == "wasd"
    assert console.model.held_keys == frozenset()
    assert console.model.velocities() == {}
    assert not any(not is_zero(r) for r in sim.received_commands())


def test_space_stops_while_a_text_box_has_focus(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    console.velocity_panel.sliders["neck"].setValue(500)  # half of the maximum
    wait_sim(qtbot, sim, lambda s: s.velocities["neck"] > 0, "neck moving from the slider")
    box = console.velocity_panel.boxes["elbow"]
    box.setFocus()
    qtbot.waitUntil(box.hasFocus, timeout=DEADLINE_MS)
    box.clear()
    QTest.keyClicks(box, "0,2")
    QTest.keyClick(box, Qt.Key.Key_Space)
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "all stopped by Space")
    assert console.model.estopped
    assert box.text() == "0.000"  # no space typed, the half-typed value is gone
    assert all(s.value() == 0 for s in console.velocity_panel.sliders.values())
    assert console.link_status.estop_label.text() == "E-STOP"
    # Nothing resumes until the operator acts again.
    mark = len(sim.received_commands())
    wait_sim(qtbot, sim, lambda s: s.rcp_count >= mark + 2, "two more RCPs")
    assert all(is_zero(r) for r in sim.received_commands()[mark:])
    QTest.keyPress(console, Qt.Key.Key_E)
    wait_sim(qtbot, sim, lambda s: s.velocities["waist"] < 0, "a new key press moves again")
    assert not console.model.estopped
    QTest.keyRelease(console, Qt.Key.Key_E)


def test_space_flagged_as_auto_repeat_still_stops(
    console: MainWindow, sim: RobotSimulator, qtbot: QtBot
) -> None:
    # Qt's xcb backend flags the first Space press after a Space release that went to
    # another window as an auto-repeat; motion started meanwhile by the mouse must stop.
    for flagged in range(2):
        console.velocity_panel.sliders["neck"].setValue(500)
        wait_sim(qtbot, sim, lambda s: s.velocities["neck"] > 0, "neck moving from the slider")
        send_key(console, QEvent.Type.KeyPress, Qt.Key.Key_Space, " ", auto=True, timestamp=T0)
        wait_zeros(qtbot, sim, f"stopped by Space flagged as a repeat ({flagged + 1})")
        assert console.model.estopped
        send_key(console, QEvent.Type.KeyRelease, Qt.Key.Key_Space, " ", timestamp=T0 + 90)
    # Space held: every auto-repeat stops again, counted on the Events dock's lines.
    lines = console.event_log.count()
    for n in range(10):
        at = T0 + 1000 + n * X_INTERVAL_MS
        send_key(console, QEvent.Type.KeyPress, Qt.Key.Key_Space, " ", auto=True, timestamp=at)
    texts = [console.event_log.item(i).text() for i in range(console.event_log.count())]
    assert len(texts) <= lines + 3, texts  # the e-stop, the link's and the halt's words
    # The console's own line (after the time's two spaces), not the link's "link: ..." one.
    counted = [t for t in texts if "  EMERGENCY STOP (Space) (×" in t]
    assert counted, texts
    assert int(counted[-1].rsplit("×", 1)[1].rstrip(")")) >= 10, texts


def test_help_overlay_shows_the_map(console: MainWindow, qtbot: QtBot) -> None:
    overlay = console.help_overlay
    assert not overlay.isVisible()
    QTest.keyClick(console, Qt.Key.Key_F1)
    assert overlay.isVisible()
    assert "drive linear: forward / reverse" in overlay.label.text()
    QTest.keyClick(console, Qt.Key.Key_Escape)
    assert not overlay.isVisible()
    QTest.keyClick(console, Qt.Key.Key_Question, Qt.KeyboardModifier.ShiftModifier)
    assert overlay.isVisible()
    QTest.keyClick(console, Qt.Key.Key_Slash)
    assert not overlay.isVisible()
