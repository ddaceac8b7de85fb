"""The built-in simulator ends with the process that started it, even one killed by SIGKILL."""

from __future__ import annotations

import os
import selectors
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

STARTUP_S = 30.0
EXIT_S = 5.0


def _stat(pid: int) -> list[str] | None:
    """The fields of /proc/PID/stat after the command name, None if there is no such process."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return None
    return text.rpartition(")")[2].split()


def _alive(pid: int) -> bool:
    """Whether the process runs (a zombie waiting for its reaper has ended)."""
    fields = _stat(pid)
    return fields is not None and fields[0] != "Z"


def _simulator_children(parent: int) -> list[int]:
    """Live `python -m ocu.sim` processes whose parent is `parent`."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        fields = _stat(int(entry.name))
        if fields is None or fields[1] != str(parent) or fields[0] == "Z":
            continue
        try:
            command = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"ocu.sim" in command:
            found.append(int(entry.name))
    return found


def _poll(predicate: object, timeout_s: float) -> bool:
    """Check a condition nothing signals (a process's end) until it holds or the deadline."""
    assert callable(predicate)
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def _wait_for_line(stream: IO[str] | None, text: str, timeout_s: float) -> str:
    """Read lines until one contains `text`; fail at the deadline."""
    assert stream is not None
    deadline = time.monotonic() + timeout_s
    seen = []
    with selectors.DefaultSelector() as selector:
        selector.register(stream, selectors.EVENT_READ)
        while (remaining := deadline - time.monotonic()) > 0 and selector.select(remaining):
            line = stream.readline()
            if not line:
                break
            seen.append(line)
            if text in line:
                return line
    raise AssertionError(f"no line with {text!r} within {timeout_s} s:\n{''.join(seen)}")


@contextmanager
def _reaped(process: subprocess.Popen[str], simulators: list[int]) -> Iterator[None]:
    """Kill whatever is left (the parent, a simulator the code under test failed to stop)."""
    try:
        yield
    finally:
        for pid in simulators:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
        if process.poll() is None:
            process.kill()
        process.wait()  # the pipes are closed by Popen's context exit


@contextmanager
def _listening(command: list[str]) -> Iterator[subprocess.Popen[str]]:
    """A simulator command started with pipes, once it says where it listens; reaped after."""
    with (
        subprocess.Popen(
            command,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        ) as process,
        _reaped(process, []),
    ):
        _wait_for_line(process.stdout, "ocu-sim listening on", STARTUP_S)
        yield process


def test_cli_stops_cleanly_at_the_end_of_stdin() -> None:
    command = [sys.executable, "-m", "ocu.sim", "--port", "0", "--video-fps", "0"]
    with _listening([*command, "--exit-with-parent"]) as process:
        assert process.stdin is not None
        process.stdin.close()
        assert process.wait(EXIT_S) == 0
        assert process.stderr is not None
        stderr = process.stderr.read()
        assert "standard input closed (parent gone)" in stderr
        assert "SIGTERM received, stopping" in stderr


PARENT = """
import signal, sys
from ocu.sim.launcher import SimulatorProcess
simulator = SimulatorProcess(extra_args=["--video-fps", "0"])
print(simulator.process.pid, flush=True)
signal.pause()
"""


_LIBRARY_THREAD = """
import signal, sys, threading
from ocu.sim import cli

go = threading.Event()

def library_thread():  # like numpy's and OpenCV's: started before the signals are blocked
    go.wait()
    signal.pthread_kill(threading.get_ident(), signal.SIGTERM)

threading.Thread(target=library_thread, daemon=True).start()
threading.Thread(target=lambda: (sys.stdin.readline(), go.set()), daemon=True).start()
sys.exit(cli.main(["--port", "0", "--video-fps", "0"]))
"""


def test_a_sigterm_given_to_a_library_thread_still_stops_cleanly() -> None:
    # The kernel gives a process's signal to any thread that does not block it.
    with _listening([sys.executable, "-c", _LIBRARY_THREAD]) as process:
        assert process.stdin is not None
        process.stdin.write("go\n")
        process.stdin.close()
        assert process.wait(EXIT_S) == 0  # not -15: the default action would skip shutdown
        assert process.stderr is not None
        stderr = process.stderr.read()
        assert "SIGTERM received, stopping" in stderr
        assert "simulator stopped" in stderr


def test_simulator_process_ends_when_its_parent_is_killed() -> None:
    simulators: list[int] = []
    with (
        subprocess.Popen(
            [sys.executable, "-c", PARENT], stdout=subprocess.PIPE, text=True
        ) as parent,
        _reaped(parent, simulators),
    ):
        simulators.append(int(_wait_for_line(parent.stdout, "", STARTUP_S)))
        assert _alive(simulators[0])
        parent.kill()
        parent.wait()
        assert _poll(lambda: not _alive(simulators[0]), EXIT_S), "the simulator outlived ocu"


def test_ocu_killed_with_sigkill_takes_its_simulator_along(tmp_path: Path) -> None:
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "OCU_CONFIG_DIR": str(tmp_path)}
    simulators: list[int] = []
    with (
        subprocess.Popen(
            [sys.executable, "-m", "ocu", "--quit-after", "120", "--sim-arg=--video-fps=0"],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        ) as ocu,
        _reaped(ocu, simulators),
    ):
        # Connected: the simulator is up and has told ocu its port.
        _wait_for_line(ocu.stderr, "link connected", STARTUP_S)
        simulators += _simulator_children(ocu.pid)
        assert len(simulators) == 1
        ocu.send_signal(signal.SIGKILL)
        ocu.wait()
        assert _poll(lambda: not _alive(simulators[0]), EXIT_S), "the simulator outlived ocu"
