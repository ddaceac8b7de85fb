"""A key whose release went to another window: the console takes it as up (real X11, Xvfb).

Qt's xcb backend keeps one auto-repeat state for the key it last saw repeating; when that
key's release goes to another window, Qt flags the key's next press in the console as an
auto-repeat. Space must stop anyway, and any other key must act on that press.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

from ocu.sim.simulator import RobotSimulator
from ocu.windows.key_filter import KEYBOARD_GAINED, KEYBOARD_LOST
from tests.test_safety import (
    OTHER_APPLICATION,
    XDOTOOL,
    find_window,
    log_shows,
    motion_after,
    read_lines,
    x_env,
    xdotool,
    xvfb,
)
from tests.windows.console_fixtures import sim

__all__ = ["sim", "xvfb"]  # fixtures used below

# Xvfb's auto-repeat: 660 ms delay, then 25 Hz; the console logs each Qt-flagged repeat.
REPEAT_SEEN = "auto-repeat flagged by Qt"
OCU = (sys.executable, "-X", "faulthandler", "-m", "ocu")


def start_ocu(env: dict[str, str], sim: RobotSimulator, log_path: Path) -> subprocess.Popen[bytes]:
    """The real program on the X display of `env`, connected to `sim`, logging key events.

    Qt's key path is what these tests are about: the X key reader (ocu.windows.x_keys,
    tests/windows/test_x_keys.py), which acts before Qt and never sees auto-repeats, is off,
    as it is where the X server has no XInput 2.2.
    """
    host, port = sim.address
    with log_path.open("w") as log:
        return subprocess.Popen(
            [*OCU, "--robot", f"{host}:{port}", "--quit-after", "60", "--log-level", "DEBUG"],
            env={**env, "OCU_X_KEYS": "0"},
            stdout=subprocess.DEVNULL,
            stderr=log,
        )


def test_a_key_released_in_another_window_acts_on_its_next_press(
    xvfb: str, sim: RobotSimulator, tmp_path: Path
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
        # W held in the console until X auto-repeats it (Qt now thinks W is repeating) ...
        focus(env, console, log_path, console=True)
        xdotool(env, "keydown", "w")
        assert sim.wait_until(lambda s: s.velocities["drive_linear"] > 0, 5.0), "no drive"
        until_qt_flags_a_repeat(program, log_path, "W")
        # ... and released in another window.
        focus(env, window.split()[0], log_path, console=False)
        assert sim.wait_until(lambda s: s.all_stopped, 3.0), "focus loss did not stop"
        xdotool(env, "keyup", "w")
        assert other.stdout is not None
        xdotool(env, "key", "x")  # the other window has the keyboard now
        assert read_lines(other.stdout, 1, 5.0) == 1
        focus(env, console, log_path, console=True)
        # Back in the console, a new press of W drives at once.
        since = time.monotonic()
        xdotool(env, "keydown", "w")
        driving = sim.wait_until(lambda s: s.velocities["drive_linear"] > 0, 3.0)
        xdotool(env, "keyup", "w")
        assert driving, f"W's first press after the lost release ignored:\n{log_path.read_text()}"
        assert sim.wait_until(lambda s: s.all_stopped, 3.0), "not stopped on W's release"
        assert motion_after(sim, since)
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


def until_qt_flags_a_repeat(program: subprocess.Popen[bytes], log_path: Path, key: str) -> None:
    """Hold on until Qt has flagged one of X's auto-repeats of the held key.

    Qt flags one only when it reads the repeat's release and press together: a busy GUI
    thread (the 3D view rendering in software) makes that likely. Where it has not happened
    after the X repeat delay, the program is frozen for a few repeat periods, as a loaded
    machine would (the stimulus, not a wait), so that the pairs queue up.
    """
    line = f"{key} {REPEAT_SEEN}"
    for _ in range(10):
        if log_shows(log_path, line, 1.5):
            return
        program.send_signal(signal.SIGSTOP)
        try:
            time.sleep(0.15)
        finally:
            program.send_signal(signal.SIGCONT)
    assert log_shows(log_path, line, 1.5), f"Qt flagged no repeat of {key}:\n{log_path.read_text()}"


def has_keyboard(log_path: Path) -> bool:
    """Whether the console's log last said it has the keyboard."""
    text = log_path.read_text()
    return text.rfind(KEYBOARD_GAINED) > text.rfind(KEYBOARD_LOST)


def focus(env: dict[str, str], window: str, log_path: Path, *, console: bool) -> None:
    """Give `window` the keyboard; wait until the console's log says it noticed."""
    xdotool(env, "windowfocus", "--sync", window)
    if console:
        xdotool(env, "mousemove", "--window", window, "9", "9")
    deadline = time.monotonic() + 10.0
    while has_keyboard(log_path) != console:  # another process's log: polled
        assert time.monotonic() < deadline, f"keyboard not followed:\n{log_path.read_text()}"
        time.sleep(0.02)


def link_stops(log_path: Path) -> int:
    """How many e-stops the link has sent (it logs each one)."""
    return log_path.read_text().count("ocu.link EMERGENCY STOP (Space)")


def test_space_released_in_another_window_still_stops_on_its_next_press(
    xvfb: str, sim: RobotSimulator, tmp_path: Path
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
        focus(env, console, log_path, console=True)
        xdotool(env, "keydown", "space")
        assert log_shows(log_path, "ocu.link EMERGENCY STOP (Space)", 5.0), log_path.read_text()
        # Space held in the console until Qt sees X auto-repeat it, released elsewhere.
        until_qt_flags_a_repeat(program, log_path, "Space")
        focus(env, window.split()[0], log_path, console=False)
        xdotool(env, "keyup", "space")
        assert other.stdout is not None
        xdotool(env, "key", "x")  # the other window has the keyboard now
        assert read_lines(other.stdout, 1, 5.0) == 1
        focus(env, console, log_path, console=True)
        flagged = log_path.read_text().count(f"Space {REPEAT_SEEN}")
        stops = link_stops(log_path)
        # Back in the console, Space pressed once: Qt calls it a repeat; it stops all the same.
        xdotool(env, "key", "space")
        deadline = time.monotonic() + 5.0
        while link_stops(log_path) == stops and time.monotonic() < deadline:
            time.sleep(0.05)  # another process's log: polled
        assert link_stops(log_path) > stops, log_path.read_text()
        # The case of the issue (Qt flagged that press) was met.
        assert log_path.read_text().count(f"Space {REPEAT_SEEN}") > flagged
    finally:
        subprocess.run([XDOTOOL or "", "keyup", "space"], env=env, timeout=30, check=False)
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
