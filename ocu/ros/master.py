"""A private `roscore` on a free port, for tests and benchmarks (ROS's own logs kept aside)."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import time
from pathlib import Path

from ocu.ros.environment import master_pid

START_TIMEOUT_S = 30.0
STOP_TIMEOUT_S = 10.0
POLL_S = 0.05
# roscore gives up (exit 1) when its rosmaster does not answer within 10 s, or when the port
# was taken between `free_port()` and its bind; a start is tried this many times, each on a
# fresh port unless one was given, and the error quotes every attempt's log.
START_ATTEMPTS = 3
LOG_TAIL_LINES = 15


class RosMasterError(RuntimeError):
    """roscore did not start."""


def free_port() -> int:
    """A TCP port nobody listens on now (the usual small race is acceptable for tests)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


class RosMaster:
    """`roscore -p PORT` as a child process; `env` holds what a ROS process needs to use it."""

    def __init__(
        self,
        work_dir: Path,
        start_timeout_s: float = START_TIMEOUT_S,
        *,
        port: int | None = None,
        attempts: int = START_ATTEMPTS,
    ) -> None:
        """`port`: a given one (a master restarted where the old one was), else a free one."""
        failures: list[str] = []
        for attempt in range(1, attempts + 1):
            self._spawn(work_dir, attempt, free_port() if port is None else port)
            try:
                self._wait_online(start_timeout_s)
                return
            except RosMasterError as error:
                self.stop()
                self._kill_leftovers()
                failures.append(f"attempt {attempt}: {error}\n{self._log_tail()}")
            except BaseException:
                self.stop()
                raise
        raise RosMasterError(
            f"roscore did not start in {attempts} attempt(s):\n" + "\n".join(failures)
        )

    def _spawn(self, work_dir: Path, attempt: int, port: int) -> None:
        self.master_pid: int | None = None  # rosmaster's, once it answers
        self.port = port
        self.uri = f"http://127.0.0.1:{self.port}"
        home = work_dir / "ros_home"
        logs = work_dir / "ros_log"
        home.mkdir(parents=True, exist_ok=True)
        logs.mkdir(parents=True, exist_ok=True)
        self.env = {
            "ROS_MASTER_URI": self.uri,
            "ROS_HOME": str(home),
            "ROS_LOG_DIR": str(logs),
            "ROS_HOSTNAME": "127.0.0.1",
        }
        name = "roscore.log" if attempt == 1 else f"roscore-{attempt}.log"
        self.log_path = work_dir / name
        self._log = self.log_path.open("wb")
        environment = {k: v for k, v in os.environ.items() if k != "ROS_IP"}
        environment.update(self.env)
        self.process = subprocess.Popen(
            ["roscore", "-p", str(self.port)],
            stdin=subprocess.DEVNULL,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            env=environment,
            start_new_session=True,
        )

    def _log_tail(self) -> str:
        """The last lines roscore printed, so that a CI log shows why it stopped."""
        try:
            lines = self.log_path.read_text(errors="replace").splitlines()
        except OSError as error:
            return f"  (roscore's log unreadable: {error})"
        if not lines:
            return "  (roscore printed nothing)"
        return "\n".join("  | " + line for line in lines[-LOG_TAIL_LINES:])

    def _wait_online(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RosMasterError(
                    f"roscore exited with code {self.process.returncode}; see {self.log_path}"
                )
            pid = master_pid(self.uri, timeout_s=1.0)
            if pid is not None:
                self.master_pid = pid
                return
            time.sleep(POLL_S)
        raise RosMasterError(f"roscore not online within {timeout_s:.0f} s; see {self.log_path}")

    def stop(self) -> None:
        """SIGINT (roscore then stops rosmaster and rosout), SIGKILL after the deadline."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, signal.SIGKILL)
                self.process.wait()
        self._log.close()
        # A rosmaster that outlived its roscore (tests once found some) would hold its port.
        pid, self.master_pid = self.master_pid, None
        if pid is not None:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)

    def _kill_leftovers(self) -> None:
        """A roscore that gave up may leave its rosmaster behind, in its group or (started
        just before roscore was stopped, under load) on its own: found by its port; and its
        rosout, which logs into this master's log folder (a test run once left one)."""
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.process.pid, signal.SIGKILL)
        wanted = f"rosmaster\0--core\0-p\0{self.port}\0".encode()
        logs = f"__log:={self.env['ROS_LOG_DIR']}/".encode()
        for entry in Path("/proc").iterdir():
            if not entry.name.isdigit():
                continue
            try:
                command = (entry / "cmdline").read_bytes()
            except OSError:
                continue
            if wanted in command or logs in command:
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.kill(int(entry.name), signal.SIGKILL)

    def __enter__(self) -> RosMaster:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
