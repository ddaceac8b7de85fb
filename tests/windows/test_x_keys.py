"""The motion keys off the GUI thread (ocu.windows.x_keys): the rules, then the real X path.

The rules run on a real console model (no X). The X tests run the real program under Xvfb
against the real simulator, press real keys with xdotool and hold the program's GUI thread
busy meanwhile: the robot must start and stop with the keys all the same.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from ocu.console.model import ConsoleModel
from ocu.hotkeys import KEY_POSITIONS, load_key_map
from ocu.profile import RobotProfile
from ocu.sim.simulator import RobotSimulator
from ocu.windows.held_keys import X_KEYCODE_OFFSET
from ocu.windows.x_keys import (
    FOCUS_IN,
    FOCUS_OUT,
    NOTIFY_INFERIOR,
    NOTIFY_POINTER,
    POINTER_ROOT,
    STARTED,
    FocusTracker,
    RawKeys,
    XKeyReader,
)
from tests.test_safety import (
    XDOTOOL,
    find_window,
    log_shows,
    motion_after,
    x_env,
    xdotool,
    xvfb,
)
from tests.windows.console_fixtures import sim

__all__ = ["sim", "xvfb"]  # fixtures used below

CTRL = 37
SHIFT = 50


def code(key: str) -> int:
    return KEY_POSITIONS[key] + X_KEYCODE_OFFSET


@pytest.fixture
def keys(profile: RobotProfile) -> tuple[RawKeys, ConsoleModel]:
    model = ConsoleModel(profile)
    return RawKeys(model, load_key_map(profile), threading.RLock()), model


def test_a_motion_key_drives_while_the_console_has_the_focus_and_stops_on_release(
    keys: tuple[RawKeys, ConsoleModel],
) -> None:
    raw, model = keys
    assert raw.key(code("W"), True, 100, focused=True)
    assert model.velocities()["drive_linear"] == model.hotkey_speed("drive_linear")
    # The release stops wherever the focus went meanwhile.
    assert raw.key(code("W"), False, 200, focused=False)
    assert model.velocities() == {}


def test_a_press_outside_the_console_or_while_typing_or_with_ctrl_is_left_alone(
    keys: tuple[RawKeys, ConsoleModel],
) -> None:
    raw, model = keys
    assert not raw.key(code("W"), True, 1, focused=False)
    raw.typing = True
    assert not raw.key(code("W"), True, 2, focused=True)
    assert raw.key(code("Space"), True, 20, focused=True)  # Space stops, typing or not
    assert model.estopped
    raw.typing = False
    raw.key(CTRL, True, 3, focused=True)
    assert not raw.key(code("W"), True, 4, focused=True)  # Ctrl+W: a shortcut, Qt's
    raw.key(CTRL, False, 5, focused=True)
    assert not raw.key(code("F1"), True, 6, focused=True)  # a command key: Qt's
    assert model.velocities() == {}
    assert not raw.key(code("W"), False, 7, focused=True)  # nothing held: nothing to stop
    assert raw.acted == 1  # Space only


def test_space_stops_everything_and_shift_is_the_fine_speed(
    keys: tuple[RawKeys, ConsoleModel],
) -> None:
    raw, model = keys
    raw.key(SHIFT, True, 1, focused=True)
    assert model.fine
    raw.key(code("W"), True, 2, focused=True)
    assert 0 < model.velocities()["drive_linear"] < model.hotkey_speed("drive_linear")
    raw.key(SHIFT, False, 3, focused=True)
    assert not model.fine
    raw.key(CTRL, True, 4, focused=True)
    assert raw.key(code("Space"), True, 5, focused=True)  # Space stops, Ctrl or not
    assert model.estopped
    assert model.velocities() == {}


def test_whoever_sees_an_event_first_acts_on_it_the_other_does_not(
    keys: tuple[RawKeys, ConsoleModel],
) -> None:
    raw, model = keys
    # Qt's key filter took the press first (its thread was idle): the reader leaves it...
    assert raw.taken.take("W", True, 42)
    assert not raw.key(code("W"), True, 42, focused=True)
    assert model.velocities() == {}
    # ...and a later event of the same key, at another server time, is the reader's.
    assert raw.key(code("W"), True, 43, focused=True)
    assert not raw.taken.take("W", True, 43)


def test_the_focus_tracker_knows_only_what_the_events_say() -> None:
    console, dock, other = 0x400001, 0x500001, 0x900001
    ours = frozenset({console, dock})
    focus = FocusTracker()
    assert not focus.known  # until asked or told
    focus.asked(other, ours)
    assert focus.known
    assert focus.window is None
    focus.event(FOCUS_IN, console, 3)  # NotifyNonlinear: from someone else's window
    assert focus.known
    assert focus.window == console
    focus.event(FOCUS_OUT, console, NOTIFY_INFERIOR)  # to a window inside it: still ours
    assert focus.window == console
    focus.event(FOCUS_OUT, console, 3)  # to the dock: out, then the dock's FocusIn
    assert focus.known
    assert focus.window is None
    focus.event(FOCUS_IN, dock, 3)
    assert focus.window == dock
    focus.event(FOCUS_OUT, console, 3)  # a late word about a window left before: ignored
    assert focus.window == dock
    focus.event(FOCUS_OUT, dock, NOTIFY_POINTER)  # the focus follows the pointer: ask
    assert not focus.known
    focus.asked(POINTER_ROOT, ours)
    assert not focus.known  # still asked at every key
    focus.asked(console, ours)
    assert focus.window == console
    focus.forget()
    assert not focus.known
    assert focus.window is None


# ---- the real program, its GUI thread held busy ------------------------------------------

# `ocu` with a way to hold its GUI thread: on SIGUSR1 a timer of the GUI thread spins in
# Python (as a long paint does) until the file given first exists.
BUSY_GUI = """
import signal, sys, time
from pathlib import Path
from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication
from ocu.app import main

app = QApplication(sys.argv[:1])
asked = []
signal.signal(signal.SIGUSR1, lambda *_: asked.append(1))
release = Path(sys.argv[1])

def poll():
    if asked:
        asked.clear()
        print("GUI thread busy", file=sys.stderr, flush=True)
        deadline = time.monotonic() + 60
        while not release.exists() and time.monotonic() < deadline:
            sum(range(2000))
        print("GUI thread free", file=sys.stderr, flush=True)

timer = QTimer()
timer.timeout.connect(poll)
timer.start(20)
sys.exit(main(sys.argv[2:]))
"""


@pytest.mark.parametrize("core", [False, True], ids=["in-process", "core-process"])
def test_keys_drive_and_stop_the_robot_while_the_gui_thread_is_busy(
    xvfb: str, sim: RobotSimulator, tmp_path: Path, core: bool
) -> None:
    # core: `ocu`'s default, the reader in the control core's process (it logs there);
    # else `ocu --in-process`.
    env = x_env(xvfb, tmp_path)
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[2])
    log_path = tmp_path / "ocu.log"
    release = tmp_path / "release"
    host, port = sim.address
    with log_path.open("w") as log:
        program = subprocess.Popen(
            [
                *(sys.executable, "-c", BUSY_GUI, str(release)),
                *("--robot", f"{host}:{port}", "--quit-after", "120", "--log-level", "DEBUG"),
                *([] if core else ["--in-process"]),
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=log,
        )
    try:
        assert sim.wait_until(lambda s: s.client is not None, 60.0), log_path.read_text()
        assert log_shows(log_path, STARTED, 30.0), log_path.read_text()
        window = find_window(env, "^ocu")
        xdotool(env, "windowfocus", "--sync", window, "mousemove", "--window", window, "9", "9")
        assert log_shows(log_path, "the console has the keyboard", 30.0), log_path.read_text()
        program.send_signal(signal.SIGUSR1)
        assert log_shows(log_path, "GUI thread busy", 30.0), log_path.read_text()
        xdotool(env, "keydown", "w")
        assert sim.wait_until(lambda s: s.velocities["drive_linear"] > 0, 10.0), (
            log_path.read_text()
        )
        xdotool(env, "keyup", "w")
        assert sim.wait_until(lambda s: s.velocities["drive_linear"] == 0, 10.0)
        xdotool(env, "keydown", "a")
        assert sim.wait_until(lambda s: s.velocities["drive_turn"] != 0, 10.0)
        xdotool(env, "key", "space")
        assert sim.wait_until(lambda s: s.all_stopped, 10.0)
        # All of it while the GUI thread was still held: it reached the robot without it.
        assert "GUI thread free" not in log_path.read_text()
        freed = time.monotonic()
        release.touch()
        assert log_shows(log_path, "GUI thread free", 30.0)
        # Then the GUI thread gets the same key events, late: each was acted on already, so
        # none acts again (a late copy of the W press would drive). Space's release is the
        # last of them and the reader leaves it to Qt: once it shows, all have been seen.
        assert log_shows(log_path, "(Qt)", 30.0), log_path.read_text()
        assert "Space released" in log_path.read_text()
        assert not motion_after(sim, freed), log_path.read_text()
        assert sim.state().all_stopped
    finally:
        release.touch()
        subprocess.run(
            [XDOTOOL or "", "keyup", "w", "keyup", "a"], env=env, timeout=30, check=False
        )
        program.send_signal(signal.SIGTERM)
        try:
            program.wait(30)
        except subprocess.TimeoutExpired:
            program.kill()
            program.wait()
    assert program.returncode == 0, log_path.read_text()
    own = "control core: a process of its own" in log_path.read_text()
    assert own == core, log_path.read_text()


def test_no_reader_where_it_is_switched_off_or_there_is_no_x_server(
    xvfb: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    reader = XKeyReader.open(xvfb)
    assert reader is not None  # Xvfb has XInput 2.2
    reader.stop()
    assert XKeyReader.open(f"{xvfb}9") is None  # no such display
    monkeypatch.setenv("OCU_X_KEYS", "0")
    assert XKeyReader.open(xvfb) is None


def foreign_window(display: str, name: bytes) -> tuple[tuple[Any, int], int]:
    """A window of another X client (this test's own connection), mapped: (connection, id)."""
    import ctypes

    x11 = ctypes.CDLL("libX11.so.6")
    vp, ul = ctypes.c_void_p, ctypes.c_ulong
    x11.XOpenDisplay.restype = vp
    x11.XOpenDisplay.argtypes = [ctypes.c_char_p]
    x11.XDefaultRootWindow.restype = ul
    x11.XDefaultRootWindow.argtypes = [vp]
    x11.XCreateSimpleWindow.restype = ul
    c_int, c_uint = ctypes.c_int, ctypes.c_uint
    x11.XCreateSimpleWindow.argtypes = [vp, ul, c_int, c_int, c_uint, c_uint, c_uint, ul, ul]
    x11.XStoreName.argtypes = [vp, ul, ctypes.c_char_p]
    x11.XMapWindow.argtypes = [vp, ul]
    x11.XSync.argtypes = [vp, ctypes.c_int]
    x11.XCloseDisplay.argtypes = [vp]
    connection = x11.XOpenDisplay(display.encode())
    assert connection
    window = x11.XCreateSimpleWindow(
        connection, x11.XDefaultRootWindow(connection), 300, 300, 200, 200, 0, 0, 0
    )
    x11.XStoreName(connection, window, name)
    x11.XMapWindow(connection, window)
    x11.XSync(connection, 0)
    return (x11, connection), window


def test_the_reader_follows_the_focus_from_x_events_not_a_query_per_key(
    xvfb: str, sim: RobotSimulator, tmp_path: Path
) -> None:
    """The X focus leaves the console for another client's window and comes back: the reader
    knows it from the focus events on its own connection (no round trip per key, each a wait
    for the GIL), so W drives while the console has the focus and not while the other has."""
    env = x_env(xvfb, tmp_path)
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[2])
    log_path = tmp_path / "ocu.log"
    host, port = sim.address
    with log_path.open("w") as log:
        program = subprocess.Popen(
            [
                *(sys.executable, "-m", "ocu"),
                *("--robot", f"{host}:{port}", "--quit-after", "120", "--log-level", "DEBUG"),
            ],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=log,
        )
    other: tuple[Any, int] | None = None
    try:
        assert sim.wait_until(lambda s: s.client is not None, 60.0), log_path.read_text()
        assert log_shows(log_path, STARTED, 30.0), log_path.read_text()
        console = find_window(env, "^ocu")
        xdotool(env, "windowfocus", "--sync", console, "mousemove", "--window", console, "9", "9")
        assert log_shows(log_path, "the console has the keyboard", 30.0), log_path.read_text()

        def drive(key: str, action: str) -> None:
            xdotool(env, f"key{action}", key)

        for _ in range(2):
            drive("w", "down")
            assert sim.wait_until(lambda s: s.velocities["drive_linear"] > 0, 10.0), (
                log_path.read_text()
            )
            drive("w", "up")
            assert sim.wait_until(lambda s: s.velocities["drive_linear"] == 0, 10.0)
        assert "(X key reader)" in log_path.read_text()

        other, other_id = foreign_window(xvfb, b"not the console")
        xdotool(env, "windowfocus", "--sync", str(other_id))
        since = time.monotonic()
        drive("w", "down")
        assert log_shows(log_path, "left to Qt (focus elsewhere)", 30.0), log_path.read_text()
        drive("w", "up")
        assert not motion_after(sim, since), log_path.read_text()

        xdotool(env, "windowfocus", "--sync", console)
        drive("w", "down")
        assert sim.wait_until(lambda s: s.velocities["drive_linear"] > 0, 10.0), (
            log_path.read_text()
        )
        drive("w", "up")
        assert sim.wait_until(lambda s: s.velocities["drive_linear"] == 0, 10.0)
        # At most one question to the server after the windows were published (none when a
        # focus event came first), not one per key.
        asked = log_path.read_text().count("X focus asked of the server")
        assert asked <= 1, log_path.read_text()
    finally:
        subprocess.run([XDOTOOL or "", "keyup", "w"], env=env, timeout=30, check=False)
        program.send_signal(signal.SIGTERM)
        try:
            program.wait(30)
        except subprocess.TimeoutExpired:
            program.kill()
            program.wait()
        if other is not None:
            library, connection = other
            library.XCloseDisplay(connection)
    assert program.returncode == 0, log_path.read_text()
