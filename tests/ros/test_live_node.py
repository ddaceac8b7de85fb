"""`ocu-ros _live:=[HOST:]PORT`: the node's session served to the npm Foxglove client."""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ocu.live.robot import TF
from ocu.profile import RobotProfile
from ocu.record import schemas as s
from ocu.ros.master import RosMaster
from ocu.ros.node import ConfigError, read_config
from ocu.sim.simulator import RobotSimulator
from tests.live.node_client import NodeClient, count, require_node
from tests.ros.conftest import ROSPY_WARNINGS, NodeProcess, wait_for

pytestmark = ROSPY_WARNINGS
SERVING = re.compile(r"live: serving on ws://127\.0\.0\.1:(\d+)")


def getter(params: dict[str, Any]) -> Any:
    def get(name: str, default: Any) -> Any:
        return params.get(name, default)

    return get


def test_live_parameters_are_read(profile: RobotProfile, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("OCU_LIVE_TOKEN", raising=False)
    assert read_config(getter({}), profile, None).live is None
    config = read_config(getter({"live": "9000"}), profile, None)
    assert (config.live, config.live_token) == (("127.0.0.1", 9000), None)
    config = read_config(
        getter({"live": "0.0.0.0:9000", "live_token": "long-enough"}), profile, None
    )
    assert (config.live, config.live_token) == (("0.0.0.0", 9000), "long-enough")
    monkeypatch.setenv("OCU_LIVE_TOKEN", "from-the-environment")
    assert read_config(getter({"live": "0.0.0.0:1"}), profile, None).live_token == (
        "from-the-environment"
    )


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"live": "0.0.0.0:9000"}, "refusing to serve a non-loopback address"),
        ({"live": "9000", "live_token": "short"}, "at least 8 characters"),
        ({"live": "h:p"}, "bad port"),
    ],
)
def test_bad_live_parameters_are_refused(
    profile: RobotProfile, monkeypatch: pytest.MonkeyPatch, params: dict[str, str], message: str
) -> None:
    monkeypatch.delenv("OCU_LIVE_TOKEN", raising=False)
    with pytest.raises(ConfigError, match=f"~live: .*{message}"):
        read_config(getter(params), profile, None)


@pytest.fixture
def sim(profile: RobotProfile) -> Iterator[RobotSimulator]:
    simulator = RobotSimulator(profile, telemetry_hz=50.0, video_fps=5.0, video_size=(160, 120))
    simulator.start()
    yield simulator
    simulator.stop()


def test_the_node_serves_its_session_live(
    ros_master: RosMaster, sim: RobotSimulator, tmp_path: Path
) -> None:
    require_node()
    node = NodeProcess(tmp_path, sim.address, "_live:=127.0.0.1:0")
    try:
        found: list[int] = []

        def serving() -> bool:
            match = SERVING.search(node.output())
            if match:
                found.append(int(match.group(1)))
            return bool(found) or node.process.poll() is not None

        assert wait_for(serving, 60.0), node.output()
        assert found, node.output()
        client = NodeClient(f"ws://127.0.0.1:{found[0]}", topics=[s.JOINT_STATES, TF], brief=True)
        try:
            assert client.wait(count(s.JOINT_STATES, 20)), node.output()
            assert client.wait(count(TF, 20))
        finally:
            client.close()
        started = time.monotonic()
        assert node.stop() == 0, node.output()
        assert time.monotonic() - started < 15.0
    finally:
        node.stop()
