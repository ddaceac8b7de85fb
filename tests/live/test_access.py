"""Who may connect: the address given, loopback by default, a token for anything else."""

from __future__ import annotations

import argparse
import json
import threading
import time
from collections.abc import Iterator

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from ocu.live.options import LiveError, check_exposure, parse_live_address
from ocu.live.server import LiveServer
from ocu.profile import RobotProfile
from tests.live.node_client import NodeClient

TOKEN = "s3cret-token-for-tests"


@pytest.mark.parametrize(
    ("text", "address"),
    [
        ("8765", ("127.0.0.1", 8765)),
        ("0.0.0.0:9000", ("0.0.0.0", 9000)),
        ("localhost:1", ("localhost", 1)),
        ("[::1]:8765", ("::1", 8765)),
    ],
)
def test_live_addresses(text: str, address: tuple[str, int]) -> None:
    assert parse_live_address(text) == address


@pytest.mark.parametrize("text", ["", "x", ":80", "host:", "host:70000", "1.2.3.4:-1"])
def test_bad_live_addresses_say_how_to_write_one(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match=r"\[HOST:\]PORT"):
        parse_live_address(text)


@pytest.mark.parametrize("host", ["127.0.0.1", "::1", "localhost", "127.0.0.5"])
def test_loopback_needs_no_token(host: str) -> None:
    check_exposure(host, None)


@pytest.mark.parametrize("host", ["0.0.0.0", "", "192.168.1.10", "::"])
def test_any_other_address_is_refused_without_a_token(host: str) -> None:
    with pytest.raises(LiveError, match="refusing to serve a non-loopback address without a token"):
        check_exposure(host, None)
    check_exposure(host, TOKEN)


def test_a_short_token_is_refused() -> None:
    with pytest.raises(LiveError, match="at least 8 characters"):
        check_exposure("0.0.0.0", "abc")


@pytest.fixture
def guarded(profile: RobotProfile) -> Iterator[LiveServer]:
    server = LiveServer(profile, "127.0.0.1", 0, token=TOKEN)
    server.start()
    try:
        yield server
    finally:
        server.stop()


def test_the_token_is_checked_at_the_handshake(guarded: LiveServer) -> None:
    url = f"ws://127.0.0.1:{guarded.address[1]}"
    for wrong in ("", "?token=nope", f"?token={TOKEN}x"):
        with pytest.raises(InvalidStatus, match="401"):
            connect(url + wrong, subprotocols=["foxglove.websocket.v1"])  # type: ignore[list-item]
    headers = {"Authorization": f"Bearer {TOKEN}"}
    with connect(url, subprotocols=["foxglove.websocket.v1"], additional_headers=headers) as ws:  # type: ignore[list-item]
        assert json.loads(ws.recv())["op"] == "serverInfo"
    client = NodeClient(f"{url}?token={TOKEN}", topics=[])
    try:
        assert client.wait(lambda events: any(e["event"] == "serverInfo" for e in events))
    finally:
        client.close()
    assert guarded.stats().unauthorized == 3


def test_both_subprotocols_are_accepted_and_no_other(guarded: LiveServer) -> None:
    url = f"ws://127.0.0.1:{guarded.address[1]}?token={TOKEN}"
    for offered in ("foxglove.websocket.v1", "foxglove.sdk.v1"):
        with connect(url, subprotocols=[offered]) as ws:  # type: ignore[list-item]
            assert ws.subprotocol == offered
    with pytest.raises(InvalidStatus, match="400"):
        connect(url, subprotocols=["chat"])  # type: ignore[list-item]


def test_an_address_in_use_is_reported(guarded: LiveServer, profile: RobotProfile) -> None:
    second = LiveServer(profile, "127.0.0.1", guarded.address[1])
    with pytest.raises(LiveError, match=f"cannot serve live on 127.0.0.1:{guarded.address[1]}"):
        second.start()


def test_clients_beyond_the_limit_are_refused(profile: RobotProfile) -> None:
    server = LiveServer(profile, "127.0.0.1", 0, max_clients=2)
    server.start()
    url = f"ws://127.0.0.1:{server.address[1]}"
    offered = ["foxglove.websocket.v1"]
    try:
        with (
            connect(url, subprotocols=offered) as first,  # type: ignore[arg-type]
            connect(url, subprotocols=offered) as second,  # type: ignore[arg-type]
        ):
            assert json.loads(first.recv())["op"] == "serverInfo"
            assert json.loads(second.recv())["op"] == "serverInfo"
            with pytest.raises(InvalidStatus, match="503"):
                connect(url, subprotocols=offered)  # type: ignore[arg-type]
        # They left: room again (once the server has seen them go).
        deadline = time.monotonic() + 10.0
        while server.stats().clients and time.monotonic() < deadline:
            threading.Event().wait(0.01)
        with connect(url, subprotocols=offered) as third:  # type: ignore[arg-type]
            assert json.loads(third.recv())["op"] == "serverInfo"
    finally:
        server.stop()
    assert server.stats().crowded == 1
