"""The robot never keeps moving because of the OCU: each case reads what the simulator received.

Focus lost, minimised, hidden, GUI thread stalled, link dropped, program closed (in process
and, under Xvfb with a Russian keyboard layout and real X11 key presses, by SIGTERM); and it
never starts because of a key held in another window when the console gets the keyboard
(under Xvfb, X's own auto-repeat).
"""

from __future__ import annotations

import os
import selectors
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO

import pytest
from PySide6.QtCore import Qt, QTimer
from PySide6.QtTest import QTest
from PySide6.QtWidgets import QWidget
from pytestqt.qtbot import QtBot

from ocu.lifecycle import SIGNAL_POLL_MS
from ocu.profile import RobotProfile
from ocu.records import LinkState
from ocu.sim.simulator import ReceivedRcp, RobotSimulator
from ocu.widgets.value_slider import STEPS
from ocu.windows.main_window import MainWindow
from tests.windows.console_fixtures import (
    DEADLINE_MS,
    ConsoleFactory,
    console,
    drive_axis,
    is_zero,
    make_console,
    settings,
    sim,
    wait_sim,
)

__all__ = ["console", "make_console", "settings", "sim"]  # fixtures used below

# A zero command must reach the robot this soon after the OCU should stop (loopback).
PROMPT_S = 0.3


def hold_forward(console: MainWindow, sim: RobotSimulator, qtbot: QtBot) -> None:
    """W held and a slider set: the robot drives and turns its neck."""
    QTest.keyPress(console, Qt.Key.Key_W)
    console.velocity_panel.sliders["neck"].setValue(STEPS // 2)
    wait_sim(
        qtbot,
        sim,
        lambda s: s.velocities["drive_linear"] > 0 and s.velocities["neck"] > 0,
        "driving forward with the neck turning",
    )


def zeros_after(sim: RobotSimulator, since: float) -> list[ReceivedRcp]:
    return [r for r in sim.received_commands() if r.time_s >= since and is_zero(r)]


def motion_after(sim: RobotSimulator, since: float) -> list[ReceivedRcp]:
    return [r for r in sim.received_commands() if r.time_s >= since and not is_zero(r)]


def assert_stopped_promptly(sim: RobotSimulator, qtbot: QtBot, since: float, why: str) -> None:
    state = wait_sim(qtbot, sim, lambda s: s.all_stopped, f"stopped: {why}")
    zeros = zeros_after(sim, since)
    assert zeros, f"no zero command on the wire after: {why}"
    assert zeros[0].time_s - since < PROMPT_S, f"zeros late after: {why}"
    assert not state.watchdog_stopped  # the OCU stopped it, not the robot's own watchdog
    assert not motion_after(sim, zeros[0].time_s), f"motion resumed after: {why}"


def test_focus_loss_stops(console: MainWindow, sim: RobotSimulator, qtbot: QtBot) -> None:
    hold_forward(console, sim, qtbot)
    other = QWidget()
    qtbot.addWidget(other)
    since = time.monotonic()
    other.show()
    other.activateWindow()
    qtbot.waitUntil(other.isActiveWindow, timeout=DEADLINE_MS)
    assert_stopped_promptly(sim, qtbot, since, "another window took the focus")
    assert console.model.held_keys == frozenset()
    # Coming back does not resume anything: the key's release went elsewhere.
    console.activateWindow()
    qtbot.waitUntil(console.isActiveWindow, timeout=DEADLINE_MS)
    mark, count = time.monotonic(), len(sim.received_commands())
    wait_sim(qtbot, sim, lambda s: s.rcp_count >= count + 2, "two more RCPs")
    assert not motion_after(sim, mark)


def test_minimising_stops(console: MainWindow, sim: RobotSimulator, qtbot: QtBot) -> None:
    hold_forward(console, sim, qtbot)
    since = time.monotonic()
    console.showMinimized()
    assert_stopped_promptly(sim, qtbot, since, "window minimised")


def test_hiding_stops(console: MainWindow, sim: RobotSimulator, qtbot: QtBot) -> None:
    hold_forward(console, sim, qtbot)
    since = time.monotonic()
    console.hide()
    assert_stopped_promptly(sim, qtbot, since, "window hidden")


def test_stalled_gui_thread_stops(
    console: MainWindow, sim: RobotSimulator, profile: RobotProfile, qtbot: QtBot
) -> None:
    QTest.keyPress(console, Qt.Key.Key_W)
    wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0, "driving forward")
    stall_s = profile.link.gui_alive_timeout_s * 2.4
    stalled: list[float] = []

    def stall() -> None:
        # The thing under test: the GUI thread stops running events (a long computation).
        stalled.append(time.monotonic())
        time.sleep(stall_s)
        stalled.append(time.monotonic())

    QTimer.singleShot(0, stall)
    qtbot.waitUntil(lambda: len(stalled) == 2, timeout=DEADLINE_MS)
    start, end = stalled
    zeros = zeros_after(sim, start)
    assert zeros, "no zeros during the stall"
    delay = zeros[0].time_s - start
    # The control thread halts the model when the GUI thread is silent for the link's
    # gui_alive_timeout_s less one heartbeat period (0.1 s) since its last sign of life
    # (which came up to 0.1 s before the stall): zeros while still stalled. The upper margin
    # is for a loaded 2-core machine.
    timeout_s = profile.link.gui_alive_timeout_s
    assert timeout_s - 0.3 <= delay <= timeout_s + 0.35, f"zeros {delay:.3f} s into the stall"
    assert zeros[0].time_s < end, "zeros only after the stall"
    # After the stall the console agrees with the link: nothing resumes, though W is held.
    wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped")
    qtbot.waitUntil(lambda: console.model.velocities() == {}, timeout=DEADLINE_MS)
    mark = len(sim.received_commands())
    wait_sim(qtbot, sim, lambda s: s.rcp_count >= mark + 2, "two more RCPs")
    resumed = motion_after(sim, zeros[0].time_s)
    assert not resumed, f"motion resumed {resumed[0].time_s - end:.3f} s after the stall"
    QTest.keyRelease(console, Qt.Key.Key_W)


def test_a_key_pressed_just_after_a_stall_with_nothing_moving_drives(
    console: MainWindow, sim: RobotSimulator, profile: RobotProfile, qtbot: QtBot
) -> None:
    stall_s = profile.link.gui_alive_timeout_s * 2.0
    pressed: list[float] = []

    def stall_then_press() -> None:
        # The GUI thread is busy with nothing moving; the operator's W is the first thing
        # it handles afterwards, before its next control tick.
        time.sleep(stall_s)
        QTest.keyPress(console, Qt.Key.Key_W)
        pressed.append(time.monotonic())

    QTimer.singleShot(0, stall_then_press)
    qtbot.waitUntil(lambda: bool(pressed), timeout=DEADLINE_MS)
    # Nothing was zeroed during the stall, so nothing stale needs stopping: W drives on.
    wait_sim(qtbot, sim, lambda s: s.velocities["drive_linear"] > 0, "driving forward")
    mark = len(sim.received_commands())
    wait_sim(qtbot, sim, lambda s: s.rcp_count >= mark + 3, "three more RCPs")
    assert not zeros_after(sim, pressed[0]), "W was dropped after the stall"
    assert console.model.held_keys
    since = time.monotonic()  # before the release: its zeros go out within keyRelease
    QTest.keyRelease(console, Qt.Key.Key_W)
    assert_stopped_promptly(sim, qtbot, since, "W released")


def test_dropped_link_stops_and_nothing_resumes(
    make_console: ConsoleFactory, sim: RobotSimulator, profile: RobotProfile, qtbot: QtBot
) -> None:
    console = make_console(sim, link_lost_after_s=1.0)
    hold_forward(console, sim, qtbot)
    cut_at = time.monotonic()
    sim.cut_link()
    # Nothing from the OCU gets through: the robot's own watchdog must stop it.
    state = wait_sim(qtbot, sim, lambda s: s.watchdog_stopped and s.all_stopped, "watchdog stop")
    assert state.time_s - cut_at < profile.link.robot_watchdog_s + 0.35
    # The console declares the link lost and stops commanding motion.
    qtbot.waitUntil(lambda: console.link_status.state == LinkState.LOST, timeout=DEADLINE_MS)
    assert console.model.velocities() == {}
    restored_at = time.monotonic()
    sim.restore_link()
    qtbot.waitUntil(lambda: console.link_status.state == LinkState.CONNECTED, timeout=DEADLINE_MS)
    mark = len(sim.received_commands())
    wait_sim(qtbot, sim, lambda s: s.rcp_count >= mark + 3, "RCPs after the link came back")
    assert not motion_after(sim, restored_at)
    assert sim.state().all_stopped


def test_closing_the_window_sends_zeros_last(
    console: MainWindow, sim: RobotSimulator, profile: RobotProfile, qtbot: QtBot
) -> None:
    hold_forward(console, sim, qtbot)
    since = time.monotonic()
    console.close()
    state = wait_sim(qtbot, sim, lambda s: s.all_stopped, "stopped on close")
    # The closing zeros are a burst: wait for all of them, not only the first to arrive.
    repeats = profile.link.estop_repeats
    wait_sim(qtbot, sim, lambda s: len(zeros_after(sim, since)) >= repeats, "the closing burst")
    received = sim.received_commands()
    tail = [(round(r.time_s - since, 4), r.packet.axes[:8], r.address) for r in received[-8:]]
    assert all(is_zero(r) for r in received[-repeats:]), tail
    # A periodic RCP already in flight when close() began may land just after `since`;
    # nothing after the first closing zero asks for motion.
    assert not motion_after(sim, zeros_after(sim, since)[0].time_s), tail
    assert not state.watchdog_stopped
    assert drive_axis(profile, received[0], "drive_linear") == 0  # sanity: axes decoded


# ---- the real program under Xvfb: a Russian layout, real key presses, SIGTERM --------------

XVFB = shutil.which("Xvfb")
XDOTOOL = shutil.which("xdotool")
SETXKBMAP = shutil.which("setxkbmap")


@pytest.fixture
def xvfb() -> Iterator[str]:
    """A private X server; its display name."""
    if not (XVFB and XDOTOOL and SETXKBMAP):
        pytest.skip("Xvfb, xdotool and setxkbmap are needed")
    read_fd, write_fd = os.pipe()
    server = subprocess.Popen(
        [
            XVFB,
            "-displayfd",
            str(write_fd),
            "-screen",
            "0",
            "1280x900x24",
            "-nolisten",
            "tcp",
            "-noreset",
        ],
        pass_fds=(write_fd,),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    os.close(write_fd)
    with os.fdopen(read_fd) as pipe:
        number = pipe.readline().strip()
    try:
        assert number, "Xvfb did not report its display"
        yield f":{number}"
    finally:
        server.terminate()
        server.wait(10)


def xdotool(env: dict[str, str], *args: str) -> str:
    result = subprocess.run(
        [XDOTOOL or "", *args], capture_output=True, text=True, env=env, timeout=30, check=True
    )
    return result.stdout


def find_window(env: dict[str, str], name_pattern: str, timeout_s: float = 30.0) -> str:
    """The first visible window whose name matches, waited for until a deadline.

    `xdotool search --sync` alone was not enough: beside two CPU hogs it once exited 1 while
    the console was starting (an X error during the search, most likely a window that went
    away while it looked; its stderr was not kept). The search is asked again until found.
    """
    deadline = time.monotonic() + timeout_s
    last = ""
    while time.monotonic() < deadline:
        result = subprocess.run(
            [XDOTOOL or "", "search", "--onlyvisible", "--name", name_pattern],
            capture_output=True,
            text=True,
            env=env,
            timeout=timeout_s,
            check=False,
        )
        windows = result.stdout.split()
        if result.returncode == 0 and windows:
            return windows[0]
        last = result.stderr.strip()
        time.sleep(0.05)  # polling the X server for a window to appear
    raise AssertionError(f"no visible window named {name_pattern!r} in {timeout_s} s ({last})")


def x_env(display: str, tmp_path: Path) -> dict[str, str]:
    env = {**os.environ, "DISPLAY": display, "QT_QPA_PLATFORM": "xcb"}
    env["OCU_CONFIG_DIR"] = str(tmp_path)
    env.pop("WAYLAND_DISPLAY", None)
    return env


def start_ocu(env: dict[str, str], sim: RobotSimulator, log_path: Path) -> subprocess.Popen[bytes]:
    """The real program on the X display of `env`, connected to `sim`; its log in log_path."""
    host, port = sim.address
    with log_path.open("w") as log:
        return subprocess.Popen(
            [
                sys.executable,
                "-X",
                "faulthandler",
                "-m",
                "ocu",
                "--robot",
                f"{host}:{port}",
                "--quit-after",
                "60",
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=log,
        )


def test_the_x_server_tells_which_keys_are_down(xvfb: str, tmp_path: Path) -> None:
    # Imported here so that the rest of this file also runs on a tree without the probe.
    from ocu.windows.held_keys import XKeymapProbe

    env = x_env(xvfb, tmp_path)
    probe = XKeymapProbe.open(xvfb)
    assert probe is not None
    try:
        assert probe.pressed() == frozenset()
        xdotool(env, "keydown", "w", "keydown", "space", "keydown", "shift")
        assert probe.pressed() == frozenset({"W", "Space"})  # Shift has no key name
        xdotool(env, "keyup", "w", "keyup", "space", "keyup", "shift")
        assert probe.pressed() == frozenset()
    finally:
        subprocess.run(
            [XDOTOOL or "", "keyup", "w", "keyup", "space", "keyup", "shift"],
            env=env,
            timeout=30,
            check=False,
        )
        probe.close()
    assert probe.pressed() is None
    assert XKeymapProbe.open(f"{xvfb}9") is None  # no such display: no probe, no error


def test_sigterm_while_driving_on_a_russian_layout_sends_zeros_last(
    xvfb: str, sim: RobotSimulator, profile: RobotProfile, tmp_path: Path
) -> None:
    env = x_env(xvfb, tmp_path)
    subprocess.run([SETXKBMAP or "", "-display", xvfb, "ru"], check=True, env=env, timeout=30)
    log_path = tmp_path / "ocu.log"
    program = start_ocu(env, sim, log_path)
    try:
        assert sim.wait_until(lambda s: s.client is not None, 30.0), "ocu never connected"
        window = find_window(env, "^ocu")
        driving = False
        for _ in range(3):  # the window may not have the keyboard focus yet: focus, retry
            xdotool(env, "windowfocus", "--sync", window, "mousemove", "--window", window, "9", "9")
            # Cyrillic_tse ('ц') sits on the W key of the Russian layout: drive forward.
            xdotool(env, "keydown", "Cyrillic_tse")
            driving = sim.wait_until(lambda s: s.velocities["drive_linear"] > 0, 3.0)
            if driving:
                break
            xdotool(env, "keyup", "Cyrillic_tse")
        assert driving, log_path.read_text()
        since = time.monotonic()
        program.send_signal(signal.SIGTERM)
        try:
            program.wait(15)
        except subprocess.TimeoutExpired:
            program.send_signal(signal.SIGABRT)
            program.wait(10)
            raise AssertionError(log_path.read_text()) from None
        stderr = log_path.read_text()
        assert program.returncode == 0, stderr
    finally:
        if program.poll() is None:
            program.kill()
            program.wait()
        subprocess.run([XDOTOOL or "", "keyup", "Cyrillic_tse"], env=env, timeout=30, check=False)
    assert sim.wait_until(lambda s: s.all_stopped, 2.0)
    received = sim.received_commands()
    assert all(is_zero(r) for r in received[-profile.link.estop_repeats :])
    # The program handles the signal within its poll period; the periodic tick may send the
    # held key's command once more before that, but nothing moves after it.
    assert not motion_after(sim, since + SIGNAL_POLL_MS / 1000 + PROMPT_S)
    assert not sim.state().watchdog_stopped  # zeros from the OCU, not the robot's watchdog
    assert "Traceback" not in stderr


# Another application: a window that prints a line for every key press it gets.
OTHER_APPLICATION = """
import sys
from PySide6.QtCore import QEvent, QObject
from PySide6.QtWidgets import QApplication, QLabel

class Presses(QObject):
    def eventFilter(self, watched, event):
        if event.type() == QEvent.Type.KeyPress and watched.isWindowType():
            print("press", flush=True)
        return False

app = QApplication(sys.argv)
presses = Presses()
app.installEventFilter(presses)
label = QLabel("another application")
label.setWindowTitle("another application")
label.resize(300, 100)
label.show()
app.exec()
"""


def read_lines(stream: IO[str], count: int, timeout_s: float) -> int:
    """Read lines from a pipe until `count` arrived or the time is up; how many arrived."""
    deadline = time.monotonic() + timeout_s
    seen = 0
    with selectors.DefaultSelector() as selector:
        selector.register(stream, selectors.EVENT_READ)
        while seen < count:
            remaining_s = deadline - time.monotonic()
            if remaining_s <= 0 or not selector.select(remaining_s):
                break
            if not stream.readline():
                break
            seen += 1
    return seen


def log_shows(path: Path, text: str, timeout_s: float) -> bool:
    """Whether the program's log shows `text` within the time (polled: it is another process)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if text in path.read_text():
            return True
        time.sleep(0.05)
    return text in path.read_text()


def test_a_key_held_in_another_window_does_not_drive_when_the_console_gets_the_focus(
    xvfb: str, sim: RobotSimulator, profile: RobotProfile, tmp_path: Path
) -> None:
    env = x_env(xvfb, tmp_path)
    log_path = tmp_path / "ocu.log"
    program = start_ocu(env, sim, log_path)
    other = subprocess.Popen(
        [sys.executable, "-c", OTHER_APPLICATION], env=env, stdout=subprocess.PIPE, text=True
    )
    try:
        assert sim.wait_until(lambda s: s.client is not None, 30.0), "ocu never connected"
        console = find_window(env, "^ocu")
        window = find_window(env, "^another appl")
        xdotool(env, "windowfocus", "--sync", window.split()[0])
        xdotool(env, "keydown", "w")
        # Xvfb auto-repeats like any X server (660 ms delay, 25 Hz): wait for the repeats.
        assert other.stdout is not None
        assert read_lines(other.stdout, 3, 5.0) == 3, "no auto-repeat in the other window"
        since = time.monotonic()
        xdotool(env, "windowfocus", "--sync", console)
        mark = len(sim.received_commands())
        assert sim.wait_until(lambda s: s.rcp_count >= mark + 3, 5.0)
        assert not motion_after(sim, since), "W held in another window drove the robot"
        # The console did get W's repeats (and says why it ignores them).
        assert log_shows(log_path, "W was already down", 5.0), log_path.read_text()
        assert not motion_after(sim, since)
        # Released and pressed again in the console: it drives, and keeps driving steadily
        # through X's auto-repeat (release+press pairs) until W goes up.
        xdotool(env, "keyup", "w")
        xdotool(env, "keydown", "w")
        assert sim.wait_until(lambda s: s.velocities["drive_linear"] > 0, 3.0), "no drive"
        started = motion_after(sim, since)[0].time_s
        assert sim.wait_until(lambda s: s.time_s > started + 1.2, 3.0)
        held = [r for r in sim.received_commands() if started <= r.time_s]
        assert all(not is_zero(r) for r in held), "the drive stuttered while W was held"
        xdotool(env, "keyup", "w")
        assert sim.wait_until(lambda s: s.all_stopped, 3.0), "not stopped on W's release"
    finally:
        subprocess.run([XDOTOOL or "", "keyup", "w"], env=env, timeout=30, check=False)
        other.kill()
        other.wait()
        if other.stdout is not None:
            other.stdout.close()
        program.terminate()
        try:
            program.wait(15)
        except subprocess.TimeoutExpired:
            program.kill()
            program.wait()
    assert "Traceback" not in log_path.read_text()
