"""A private `roscore` on a free port, for tests and benchmarks (ROS's own logs kept aside)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import time
from pathlib import Path

from ocu.ros.environment import master_online

START_TIMEOUT_S = 30.0
STOP_TIMEOUT_S = 10.0
POLL_S = 0.05


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
        self, work_dir: Path, start_timeout_s: float = START_TIMEOUT_S, *, port: int | None = None
    ) -> None:
        """`port`: a given one (a master restarted where the old one was), else a free one."""
        self.port = free_port() if port is None else port
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
        self.log_path = work_dir / "roscore.log"
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
        try:
            self._wait_online(start_timeout_s)
        except BaseException:
            self.stop()
            raise

    def _wait_online(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RosMasterError(
                    f"roscore exited with code {self.process.returncode}; see {self.log_path}"
                )
            if master_online(self.uri, timeout_s=1.0):
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

    def __enter__(self) -> RosMaster:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
