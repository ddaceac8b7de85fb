"""Start `ocu-sim` as a child process and learn the port it listens on."""

from __future__ import annotations

import re
import selectors
import subprocess
import sys
import time
from pathlib import Path

LISTENING_LINE = re.compile(r"ocu-sim listening on (?P<host>[^:\s]+):(?P<port>\d+)")


class SimulatorProcessError(RuntimeError):
    """The simulator process did not start or did not say where it listens."""


class SimulatorProcess:
    """A simulator child process; stop() is idempotent and also runs on context exit."""

    def __init__(
        self,
        profile_path: str | Path | None = None,
        extra_args: list[str] | None = None,
        start_timeout_s: float = 15.0,
    ) -> None:
        command = [sys.executable, "-m", "ocu.sim", "--host", "127.0.0.1", "--port", "0"]
        if profile_path is not None:
            command += ["--profile", str(profile_path)]
        command += extra_args or []
        self.process = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=None, text=True, bufsize=1
        )
        try:
            self.address = self._read_address(start_timeout_s)
        except BaseException:
            self.stop()
            raise

    def _read_address(self, timeout_s: float) -> tuple[str, int]:
        assert self.process.stdout is not None
        deadline = time.monotonic() + timeout_s
        with selectors.DefaultSelector() as selector:
            selector.register(self.process.stdout, selectors.EVENT_READ)
            while time.monotonic() < deadline:
                if not selector.select(deadline - time.monotonic()):
                    break
                line = self.process.stdout.readline()
                if not line:
                    raise SimulatorProcessError(
                        f"simulator exited with code {self.process.wait()} before listening"
                    )
                match = LISTENING_LINE.search(line)
                if match:
                    return match["host"], int(match["port"])
        raise SimulatorProcessError(f"simulator did not report its port within {timeout_s:.0f} s")

    def stop(self, timeout_s: float = 5.0) -> None:
        """Terminate the process (kill after the deadline) and close its pipe."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.process.stdout is not None:
            self.process.stdout.close()

    def __enter__(self) -> SimulatorProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
