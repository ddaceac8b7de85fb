"""However the console ends while driving, zeros are the last datagrams the robot received.

The real program under Xvfb, driven by a real X key press, ended by SIGHUP (a closed terminal,
a dropped SSH session), SIGQUIT (Ctrl-\\) or its X server dying; a console without Qt ended by
an unhandled exception; an exception in one of the console's threads. The simulator in this
process records what it received.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from ocu.link.guard import ExitGuard
from ocu.link.live import UdpLink
from ocu.nav.world import default_world_path, load_world
from ocu.profile import RobotProfile
from ocu.sim.simulator import RobotSimulator
from tests.test_safety import XDOTOOL, XVFB, find_window, start_ocu, x_env, xdotool
from tests.windows.console_fixtures import is_zero, sim

__all__ = ["sim"]  # fixture used below

DEADLINE_S = 15.0
ROOT = Path(__file__).resolve().parents[1]
X_OPTIONS = ("-nolisten", "tcp", "-noreset")


class XServer:
    """A private Xvfb this test may kill."""

    def __init__(self) -> None:
        read_fd, write_fd = os.pipe()
        self.process = subprocess.Popen(
            [XVFB or "", "-displayfd", str(write_fd), "-screen", "0", "1280x900x24", *X_OPTIONS],
            pass_fds=(write_fd,),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        os.close(write_fd)
        with os.fdopen(read_fd) as pipe:
            number = pipe.readline().strip()
        assert number, "Xvfb did not report its display"
        self.display = f":{number}"

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait(10)


@pytest.fixture
def x_server() -> Iterator[XServer]:
    if not (XVFB and XDOTOOL):
        pytest.skip("Xvfb and xdotool are needed")
    server = XServer()
    try:
        yield server
    finally:
        server.kill()


def drive_by_key(env: dict[str, str], sim: RobotSimulator, log_path: Path) -> None:
    """W held down in the console's window (real X key events): the robot drives."""
    assert sim.wait_until(lambda s: s.client is not None, 30.0), log_path.read_text()
    window = find_window(env, "^ocu")
    for _ in range(3):  # the window may not have the keyboard focus yet: focus, retry
        xdotool(env, "windowfocus", "--sync", window, "mousemove", "--window", window, "9", "9")
        xdotool(env, "keydown", "w")
        if sim.wait_until(lambda s: s.velocities["drive_linear"] > 0, 3.0):
            return
        xdotool(env, "keyup", "w")
    raise AssertionError(f"never drove\n{log_path.read_text()}")


def assert_zeros_last(sim: RobotSimulator, profile: RobotProfile, log_text: str) -> None:
    """The robot stopped because the OCU said so: a zero burst is the last thing it got."""
    assert sim.wait_until(lambda s: s.all_stopped, 2.0), log_text
    received = sim.received_commands()
    tail = received[-profile.link.estop_repeats :]
    assert all(is_zero(r) for r in tail), (tail, log_text)
    # Zeros from the OCU, not the robot's own watchdog: they came within its timeout.
    last_motion = max(i for i, r in enumerate(received) if not is_zero(r))
    gap_s = received[last_motion + 1].time_s - received[last_motion].time_s
    assert gap_s < profile.link.robot_watchdog_s, (gap_s, log_text)


def end_program(program: subprocess.Popen[bytes], log_path: Path) -> int:
    try:
        return program.wait(DEADLINE_S)
    except subprocess.TimeoutExpired:
        program.send_signal(signal.SIGABRT)
        program.wait(10)
        raise AssertionError(log_path.read_text()) from None


@pytest.mark.parametrize("sig", [signal.SIGHUP, signal.SIGQUIT], ids=["SIGHUP", "SIGQUIT"])
def test_a_stop_signal_while_driving_sends_zeros_last(
    x_server: XServer,
    sim: RobotSimulator,
    profile: RobotProfile,
    tmp_path: Path,
    sig: signal.Signals,
) -> None:
    env = x_env(x_server.display, tmp_path)
    log_path = tmp_path / "ocu.log"
    program = start_ocu(env, sim, log_path)
    try:
        drive_by_key(env, sim, log_path)
        program.send_signal(sig)
        code = end_program(program, log_path)
    finally:
        if program.poll() is None:
            program.kill()
            program.wait()
    text = log_path.read_text()
    assert code == 0, text
    assert f"{sig.name} received, quitting" in text
    assert "Traceback" not in text
    assert_zeros_last(sim, profile, text)


@pytest.fixture
def sim_with_video(profile: RobotProfile) -> Iterator[RobotSimulator]:
    """The simulator with its camera on: the console paints video (through Xlib, as GL)."""
    world = load_world(default_world_path())
    simulator = RobotSimulator(profile, telemetry_hz=10.0, video_fps=15.0, world=world)
    simulator.start()
    yield simulator
    simulator.stop()


def test_the_x_server_dying_while_driving_sends_zeros_last(
    x_server: XServer, sim_with_video: RobotSimulator, profile: RobotProfile, tmp_path: Path
) -> None:
    # Qt's xcb plugin may notice first and quit in order; Xlib, when a paint notices first,
    # ends the process from its fatal I/O error handler (C's exit(): no Python teardown).
    sim = sim_with_video
    env = x_env(x_server.display, tmp_path)
    log_path = tmp_path / "ocu.log"
    program = start_ocu(env, sim, log_path)
    try:
        drive_by_key(env, sim, log_path)
        x_server.kill()
        end_program(program, log_path)
    finally:
        if program.poll() is None:
            program.kill()
            program.wait()
    assert_zeros_last(sim, profile, log_path.read_text())


# The exception is still reported (the hook it replaced, here pytest's, gets it too).
@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_an_unhandled_exception_in_a_thread_sends_the_zero_burst(
    sim: RobotSimulator, profile: RobotProfile
) -> None:
    link = UdpLink(profile, sim.address, gui_alive_timeout_s=None)
    link.start()
    try:
        with ExitGuard():
            link.set_velocities(neck=0.3)
            assert sim.wait_until(lambda s: s.velocities["neck"] > 0, DEADLINE_S)
            before = len(sim.received_commands())

            def fail() -> None:
                raise RuntimeError("a bug in a console thread")

            thread = threading.Thread(target=fail, name="ocu-test-failing")
            thread.start()
            thread.join()
            repeats = profile.link.estop_repeats
            assert sim.wait_until(lambda s: s.rcp_count >= before + repeats, DEADLINE_S)
            after = sim.received_commands()[before:]
            assert len(after) >= repeats
            assert all(is_zero(r) for r in after), after
            assert link.command.is_motion is False
    finally:
        link.shutdown()


def test_an_unhandled_exception_in_the_main_thread_ends_with_zeros(
    sim: RobotSimulator, profile: RobotProfile
) -> None:
    host, port = sim.address
    with subprocess.Popen(
        [sys.executable, "-m", "tests.link.drive_child", host, str(port), "crash"],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    ) as child:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "driving"
        assert sim.wait_until(lambda s: s.velocities["neck"] > 0, DEADLINE_S), "never drove"
        _, stderr = child.communicate("crash\n", timeout=60)
    assert "RuntimeError: the console failed" in stderr
    assert child.returncode == 1
    assert_zeros_last(sim, profile, stderr)


# Xlib's own path, made certain: a display of our own notices the lost server, and Xlib calls
# its fatal I/O error handler (ocu.lifecycle's hook, then Qt's or the default) and then exit().
XLIB_LOSS = """
import ctypes, sys
from PySide6.QtWidgets import QApplication
from ocu.lifecycle import last_zeros_guard
from ocu.link.live import UdpLink
from ocu.profile import load_profile

app = QApplication([])
link = UdpLink(load_profile(), (sys.argv[1], int(sys.argv[2])), gui_alive_timeout_s=None)
link.start()
xlib = ctypes.CDLL("libX11.so.6")
xlib.XOpenDisplay.restype = ctypes.c_void_p
xlib.XOpenDisplay.argtypes = [ctypes.c_char_p]
xlib.XSync.argtypes = [ctypes.c_void_p, ctypes.c_int]
with last_zeros_guard():
    display = xlib.XOpenDisplay(None)
    link.set_velocities(neck=0.3)
    print("driving", flush=True)
    sys.stdin.readline()
    xlib.XSync(display, 0)
print("not reached", flush=True)
"""


def test_xlib_ending_the_process_on_a_lost_x_server_sends_zeros_first(
    x_server: XServer, sim: RobotSimulator, profile: RobotProfile, tmp_path: Path
) -> None:
    host, port = sim.address
    env = x_env(x_server.display, tmp_path)
    env["PYTHONPATH"] = str(ROOT)
    with subprocess.Popen(
        [sys.executable, "-c", XLIB_LOSS, host, str(port)],
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    ) as child:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "driving"
        assert sim.wait_until(lambda s: s.velocities["neck"] > 0, DEADLINE_S), "never drove"
        x_server.kill()
        stdout, stderr = child.communicate("\n", timeout=60)
    assert "not reached" not in stdout
    assert "XIO" in stderr  # Xlib's handler ran and ended the process
    assert "X server connection lost: shutting the link down" in stderr
    assert_zeros_last(sim, profile, stderr)
