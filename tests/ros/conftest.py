"""A real roscore for the ROS tests, this process as a ROS node, and the node under test."""

from __future__ import annotations

import gc
import itertools
import os
import signal
import subprocess
import sys
import threading
import time
import warnings
import xmlrpc.client
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from ocu.ros.environment import missing_ros
from ocu.ros.master import RosMaster

ROS_MISSING = missing_ros()
# Debian's rospy (Noetic) calls threading's notifyAll() and logging's warn() from its own
# threads, and leaves its XML-RPC sockets to the garbage collector; with warnings as errors
# those would raise inside rospy's threads (or wherever the collector runs) and break it.
ROSPY_WARNINGS = [
    pytest.mark.filterwarnings("ignore::DeprecationWarning:rospy"),
    pytest.mark.filterwarnings("ignore::DeprecationWarning:rosgraph"),
    pytest.mark.filterwarnings("ignore::ResourceWarning"),
]
NODE_START_TIMEOUT_S = 20.0
NODE_STOP_TIMEOUT_S = 15.0
_names = itertools.count(1)


def needs_ros() -> None:
    """Skip with the reason when Debian's ROS 1 packages are absent; with OCU_REQUIRE_ROS=1
    (CI, which installs them) fail instead, so the ROS tests cannot silently stop running."""
    if ROS_MISSING is None:
        return
    if os.environ.get("OCU_REQUIRE_ROS") == "1":
        pytest.fail(ROS_MISSING)
    pytest.skip(ROS_MISSING)


@pytest.fixture(scope="package")
def ros_master(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RosMaster]:
    """`roscore -p <free port>` for the ROS tests; this process's environment points at it."""
    needs_ros()
    master = RosMaster(tmp_path_factory.mktemp("ros"))
    saved = {key: os.environ.get(key) for key in master.env}
    os.environ.update(master.env)
    try:
        yield master
    finally:
        master.stop()
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


@pytest.fixture(scope="package")
def ros_client(ros_master: RosMaster) -> Iterator[None]:
    """This test process as an anonymous ROS node (rospy allows one per process)."""
    import rospy

    from ocu.ros.topics import init_node

    init_node("ocu_tests", anonymous=True)
    yield
    rospy.signal_shutdown("tests finished")
    # Collect rospy's abandoned sockets now rather than during some later test.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        gc.collect()


def wait_for(predicate: Callable[[], bool], timeout_s: float) -> bool:
    """Poll a condition that has no event of its own (ROS connection counts), with a deadline."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


class NodeProcess:
    """`python -m ocu.ros.node` as a child with a unique node name; output kept in a file."""

    def __init__(
        self,
        work_dir: Path,
        robot: tuple[str, int] | None,
        *args: str,
        name: str | None = None,
        env: dict[str, str] | None = None,
    ) -> None:
        """`env`: variables over this process's (another master's ROS_MASTER_URI); `robot`
        None: no `_robot` (the node's built-in simulator)."""
        self.name = name or f"ocu_ros_test_{next(_names)}"
        self.log_path = work_dir / f"{self.name}_{next(_names)}.log"
        command = [
            sys.executable,
            "-m",
            "ocu.ros.node",
            f"__name:={self.name}",
            *([f"_robot:={robot[0]}:{robot[1]}"] if robot is not None else []),
            *args,
        ]
        self._log = self.log_path.open("wb")
        self.process = subprocess.Popen(
            command,
            stdin=subprocess.DEVNULL,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            env=dict(os.environ, PYTHONUNBUFFERED="1", **(env or {})),
        )

    def output(self) -> str:
        """Everything the node printed so far."""
        return self.log_path.read_text(encoding="utf-8", errors="replace")

    def wait_connected(self, publisher: Any, timeout_s: float = NODE_START_TIMEOUT_S) -> None:
        """Wait until this node's subscriber is connected to `publisher` (others may be too)."""
        caller_id = f"/{self.name}"
        if not wait_for(
            lambda: publisher.impl.has_connection(caller_id) or self.process.poll() is not None,
            timeout_s,
        ):
            raise AssertionError(f"{self.name} did not subscribe:\n{self.output()}")
        if self.process.poll() is not None:
            raise AssertionError(f"{self.name} exited {self.process.returncode}:\n{self.output()}")

    def wait_exit(self, timeout_s: float = NODE_START_TIMEOUT_S) -> int:
        """The exit code of a node that stops by itself (AssertionError if it does not)."""
        try:
            return self.process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            code = self.stop()
            raise AssertionError(
                f"{self.name} still ran after {timeout_s} s (then exited {code}):\n" + self.output()
            ) from None
        finally:
            self._log.close()

    def stop(self, sig: int = signal.SIGTERM) -> int:
        """Send a signal and wait for the exit code (kill after the deadline)."""
        if self.process.poll() is None:
            self.process.send_signal(sig)
            try:
                self.process.wait(NODE_STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        self._log.close()
        return self.process.returncode


class Collector:
    """Subscribes to a topic and keeps every message; tests wait on it with deadlines."""

    def __init__(self, topic: str, message_type: Any) -> None:
        import rospy

        self.messages: list[Any] = []
        self._cond = threading.Condition()
        self._subscriber = rospy.Subscriber(topic, message_type, self._add)

    def _add(self, message: Any) -> None:
        with self._cond:
            self.messages.append(message)
            self._cond.notify_all()

    def count(self) -> int:
        """How many messages arrived so far (for `wait(after=...)`)."""
        with self._cond:
            return len(self.messages)

    def wait(
        self, predicate: Callable[[Any], bool], timeout_s: float = 10.0, *, after: int = 0
    ) -> Any:
        """The first message (old or new, from index `after` on) that satisfies predicate;
        AssertionError if none."""
        found: list[Any] = []

        def check() -> bool:
            found[:] = [m for m in self.messages[after:] if predicate(m)][:1]
            return bool(found)

        with self._cond:
            if not self._cond.wait_for(check, timeout_s):
                raise AssertionError(f"no matching message in {len(self.messages)} received")
        return found[0]

    def wait_connected(self, node_name: str, timeout_s: float = 10.0) -> None:
        """Wait until this subscriber is connected to a node's publisher of the topic."""
        uri = node_uri(node_name)
        if not wait_for(lambda: self._subscriber.impl.has_connection(uri), timeout_s):
            raise AssertionError(f"not connected to /{node_name} ({uri})")

    def close(self) -> None:
        self._subscriber.unregister()


def node_uri(node_name: str) -> str:
    """The XML-RPC URI a node registered with the master (rospy names connections by it)."""
    master = xmlrpc.client.ServerProxy(os.environ["ROS_MASTER_URI"])
    try:
        reply = master.lookupNode("/ocu_tests", f"/{node_name}")
    finally:
        master("close")()
    if not (isinstance(reply, list) and reply[0] == 1):
        raise AssertionError(f"master does not know /{node_name}: {reply!r}")
    return str(reply[2])
