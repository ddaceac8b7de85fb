"""Start `ocu-sim` as a child process and learn the port it listens on.

The child is started with `--exit-with-parent` and its standard input a pipe that only this
process writes to: when this process ends in any way, SIGKILL included, the kernel closes
the pipe and the simulator stops itself instead of running on, orphaned.
"""

from __future__ import annotations

import logging
import re
import selectors
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from ocu.priority import reset_for_child

log = logging.getLogger("ocu.sim")

LISTENING_LINE = re.compile(r"ocu-sim listening on (?P<host>[^:\s]+):(?P<port>\d+)")


def with_default_world(sim_args: Sequence[str]) -> list[str]:
    """The console's simulator arguments: the shipped room unless they name a world."""
    if any(arg == "--world" or arg.startswith("--world=") for arg in sim_args):
        return list(sim_args)
    return ["--world", "default", *sim_args]


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
        command.append("--exit-with-parent")
        if profile_path is not None:
            command += ["--profile", str(profile_path)]
        command += extra_args or []
        # The simulator stands in for the robot: not at the console's raised priority.
        command = reset_for_child(command)
        # Nothing is ever written to stdin: the pipe is there to be closed when we die.
        self.process = subprocess.Popen(
            command,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=None,
            text=True,
            bufsize=1,
        )
        try:
            self.address = self._read_address(start_timeout_s)
            log.info("simulator pid %d listening on %s:%d", self.process.pid, *self.address)
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
        for pipe in (self.process.stdin, self.process.stdout):
            if pipe is not None:
                pipe.close()

    def __enter__(self) -> SimulatorProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
