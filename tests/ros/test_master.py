"""The private roscore of the ROS tests: a start that fails is retried and explained."""

from __future__ import annotations

import socket
import threading
import time
import xmlrpc.client
from pathlib import Path
from typing import Any

import pytest

from ocu.ros.environment import master_online
from ocu.ros.master import RosMaster, RosMasterError
from tests.ros.conftest import needs_ros

DEADLINE_S = 60.0


def test_a_port_taken_at_the_first_start_is_retried_and_the_first_log_kept(
    tmp_path: Path,
) -> None:
    """CI once saw roscore exit 1 at the first ROS test and every ROS test fail with it; the
    port a master is given can be taken between the choice and the bind. Here another server
    (one that hangs up at once) holds it during the first attempt and lets go once roscore
    has said so."""
    needs_ros()
    holder = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    holder.bind(("0.0.0.0", 0))
    holder.listen()
    holder.settimeout(0.1)
    port = int(holder.getsockname()[1])

    def hang_up() -> None:
        while not released.is_set():
            try:
                connection, _ = holder.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            connection.close()

    first_log = tmp_path / "roscore.log"
    released = threading.Event()

    def release_when_refused() -> None:
        deadline = time.monotonic() + DEADLINE_S
        while time.monotonic() < deadline:
            if first_log.exists() and "already in use" in first_log.read_text(errors="replace"):
                holder.close()
                released.set()
                return
            time.sleep(0.05)
        holder.close()

    threading.Thread(target=hang_up, daemon=True).start()
    watcher = threading.Thread(target=release_when_refused, daemon=True)
    watcher.start()
    try:
        master = RosMaster(tmp_path, port=port, attempts=2)
    finally:
        watcher.join(DEADLINE_S)
    try:
        assert released.is_set(), "the first roscore never reported the taken port"
        assert master.port == port
        assert master.log_path.name == "roscore-2.log"
        assert master_online(master.uri, timeout_s=5.0)
        assert "already in use" in first_log.read_text(errors="replace")
        wait_for_rosout(master)
    finally:
        master.stop()


def wait_for_rosout(master: RosMaster) -> None:
    """roscore stops promptly on SIGINT once its rosout runs (before, it takes 10 s)."""
    deadline = time.monotonic() + DEADLINE_S
    with xmlrpc.client.ServerProxy(master.uri) as proxy:
        while time.monotonic() < deadline:
            state: Any = proxy.getSystemState("/test")
            publishers = state[2][0]
            if any(topic == "/rosout_agg" for topic, _ in publishers):
                return
            time.sleep(0.05)
    raise AssertionError("rosout never published /rosout_agg")


def test_a_master_that_never_comes_up_is_an_error_quoting_each_attempt(tmp_path: Path) -> None:
    needs_ros()
    with pytest.raises(RosMasterError) as raised:
        RosMaster(tmp_path, start_timeout_s=0.0, attempts=2)
    text = str(raised.value)
    assert "did not start in 2 attempt(s)" in text
    assert "attempt 1: roscore not online within 0 s" in text
    assert "attempt 2: roscore not online within 0 s" in text
    assert (tmp_path / "roscore.log").exists()
    assert (tmp_path / "roscore-2.log").exists()
