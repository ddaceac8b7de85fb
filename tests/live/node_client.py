"""The npm Foxglove client (tests/live/js/client.js) run by Node.js, read from pytest."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

JS_DIR = Path(__file__).parent / "js"
DEADLINE_S = 30.0
NODE_MISSING = (
    "Node.js and the npm client are needed: `./dev test` installs them "
    "(Debian's nodejs and npm, then `npm ci` in tests/live/js)"
)


def require_node() -> str:
    """The node executable; skip the test when Node.js or the npm packages are missing - fail
    instead under `./dev test` once it installed them (OCU_REQUIRE_NODE=1), as for ROS."""
    node = shutil.which("node")
    if node is None or not (JS_DIR / "node_modules" / "@foxglove" / "ws-protocol").is_dir():
        if os.environ.get("OCU_REQUIRE_NODE") == "1":
            pytest.fail(NODE_MISSING + " (OCU_REQUIRE_NODE=1)")
        pytest.skip(NODE_MISSING)
    return node


class NodeClient:
    """One client process; its printed events collected on a thread of its own."""

    def __init__(self, url: str, **options: Any) -> None:
        node = require_node()
        self.events: list[dict[str, Any]] = []
        self._cond = threading.Condition()
        self.process = subprocess.Popen(
            [node, str(JS_DIR / "client.js"), json.dumps({"url": url, **options})],
            cwd=JS_DIR,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self._reader = threading.Thread(target=self._read, name="node-client", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            event = json.loads(line)
            if "receive_ns" in event:
                event["receive_ns"] = int(event["receive_ns"])  # a uint64, as text
            with self._cond:
                self.events.append(event)
                self._cond.notify_all()
        with self._cond:
            self.events.append({"event": "exit"})
            self._cond.notify_all()

    def wait(
        self, predicate: Callable[[list[dict[str, Any]]], bool], timeout_s: float = DEADLINE_S
    ) -> bool:
        """Whether the events met the predicate before the deadline."""
        with self._cond:
            return self._cond.wait_for(lambda: predicate(self.events), timeout_s)

    def messages(self, topic: str) -> list[dict[str, Any]]:
        """The messages received on a topic so far."""
        with self._cond:
            return [e for e in self.events if e["event"] == "message" and e["topic"] == topic]

    def of(self, kind: str) -> list[dict[str, Any]]:
        """Events of one kind so far."""
        with self._cond:
            return [e for e in self.events if e["event"] == kind]

    def close(self) -> None:
        """Close the connection, then the process (killed after the deadline)."""
        if self.process.stdin is not None and not self.process.stdin.closed:
            with contextlib.suppress(BrokenPipeError):
                self.process.stdin.close()
        try:
            self.process.wait(10.0)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(10.0)
        self._reader.join(10.0)
        for stream in (self.process.stdout, self.process.stderr):
            if stream is not None:
                stream.close()


def count(topic: str, n: int) -> Callable[[list[dict[str, Any]]], bool]:
    """A predicate: at least n messages on the topic."""
    return lambda events: (
        sum(1 for e in events if e["event"] == "message" and e["topic"] == topic) >= n
    )


def wall_ms() -> float:
    """Now, as the client stamps arrivals (ms since the epoch)."""
    return time.time() * 1000.0
