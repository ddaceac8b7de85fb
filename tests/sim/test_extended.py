"""The simulator's protocol extension over real UDP: detection, four cameras, status."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator
from typing import Any

import cv2
import numpy as np
import pytest

from ocu.link.reassembly import Reassembler
from ocu.profile import RobotProfile
from ocu.protocol.extended import HelloPacket, StatusPacket, VideoFragment
from ocu.protocol.mapping import CommandMapper
from ocu.protocol.wire import make_codec, make_extension_codec
from ocu.records import CameraRequest, Command
from ocu.sim.cli import build_parser
from ocu.sim.extended import jpeg_comment
from ocu.sim.simulator import RobotSimulator
from ocu.sim.video import parse_comment

WAIT_S = 5.0


class ExtendedClient:
    """A bare OCU: sends hellos and RCPs, reassembles what comes back."""

    def __init__(self, profile: RobotProfile, target: tuple[str, int]) -> None:
        codec = make_extension_codec(profile)
        assert codec is not None
        self.codec = codec
        self.vendor = make_codec(profile)
        self.mapper = CommandMapper(profile)
        self.target = target
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.reassembler = Reassembler(16, 8 << 20, 1.0)
        self.frames: dict[int, list[dict[str, str]]] = {}
        self.status: list[StatusPacket] = []
        self.vendor_video = 0

    def hello(self, *requests: CameraRequest) -> None:
        self.sock.sendto(self.codec.encode(HelloPacket(cameras=requests)), self.target)

    def rcp(self, command: Command) -> None:
        self.sock.sendto(self.vendor.encode(self.mapper.to_packet(command)), self.target)

    def pump(self, seconds: float, *, hello: tuple[CameraRequest, ...] | None = None) -> None:
        """Receive for a while, saying hello (and sending an RCP) every 0.2 s if asked."""
        deadline = time.monotonic() + seconds
        next_hello = 0.0
        while (now := time.monotonic()) < deadline:
            if hello is not None and now >= next_hello:
                self.hello(*hello)
                next_hello = now + 0.2
            self.sock.settimeout(min(0.05, max(deadline - now, 0.001)))
            try:
                data = self.sock.recv(70_000)
            except TimeoutError:
                continue
            if self.codec.handles(data[0]):
                packet = self.codec.decode(data)
                if isinstance(packet, StatusPacket):
                    self.status.append(packet)
                elif isinstance(packet, VideoFragment):
                    done = self.reassembler.add(packet, time.monotonic())
                    if done is not None:
                        comment = jpeg_comment(done.jpeg)
                        assert comment is not None
                        image = cv2.imdecode(np.frombuffer(done.jpeg, np.uint8), cv2.IMREAD_COLOR)
                        assert image is not None
                        facts = parse_comment(comment)
                        facts["decoded"] = f"{image.shape[1]}x{image.shape[0]}"
                        self.frames.setdefault(done.camera, []).append(facts)
            elif data[0] == self.vendor.video_type:
                self.vendor_video += 1

    def drain(self) -> None:
        """Discard what is queued."""
        self.sock.setblocking(False)
        try:
            while True:
                self.sock.recv(70_000)
        except BlockingIOError:
            pass
        finally:
            self.sock.setblocking(True)

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def sim(profile: RobotProfile, request: pytest.FixtureRequest) -> Iterator[RobotSimulator]:
    options: dict[str, Any] = {"telemetry_hz": 5.0, "video_fps": 10.0, "seed": 3}
    options.update(getattr(request, "param", {}))
    simulator = RobotSimulator(profile, **options)
    simulator.start()
    yield simulator
    simulator.stop()
    assert simulator.state().internal_errors == 0


@pytest.fixture
def client(profile: RobotProfile, sim: RobotSimulator) -> Iterator[ExtendedClient]:
    ocu = ExtendedClient(profile, sim.address)
    yield ocu
    ocu.close()


SMALL = tuple(CameraRequest(k, 160, 120, 10) for k in range(4))


def test_vendor_simulator_drops_the_hello_as_foreign(
    sim: RobotSimulator, client: ExtendedClient
) -> None:
    client.rcp(Command())
    client.pump(0.6, hello=SMALL)
    state = sim.state()
    assert state.foreign_count >= 3
    assert state.malformed_count == 0
    assert state.extended is None
    assert client.status == []
    assert client.frames == {}
    assert client.vendor_video > 0


@pytest.mark.parametrize("sim", [{"extended": True}], indirect=True)
def test_extended_simulator_streams_every_requested_camera(
    sim: RobotSimulator, client: ExtendedClient
) -> None:
    requests = (
        CameraRequest(0, 160, 120, 10),
        CameraRequest(1, 320, 240, 10, quality=30),
        CameraRequest(2, 160, 120, 0),  # switched off
        CameraRequest(3, 176, 144, 20),
    )
    client.rcp(Command(torch=True))
    client.pump(1.5, hello=requests)
    assert client.status, "no status packet"
    assert set(client.frames) == {0, 1, 3}
    for camera, frames in client.frames.items():
        assert all(f["index"] == str(camera) for f in frames)
        request = requests[camera]
        size = f"{request.width_px}x{request.height_px}"
        assert all(f["size"] == size and f["decoded"] == size for f in frames)
        assert [int(f["frame"]) for f in frames] == sorted(int(f["frame"]) for f in frames)
    assert all(f["quality"] == "30" for f in client.frames[1])
    assert all(f["torch"] == "1" for f in client.frames[0])
    # 20 fps asked of camera 3, 10 of camera 0: about twice as many frames.
    assert len(client.frames[3]) > 1.5 * len(client.frames[0])
    assert client.vendor_video == 0  # the extension replaces the vendor stream
    status = client.status[-1]
    assert status.headlight_on is True
    assert status.camera_count == 4
    assert status.voltage_mv is not None
    assert status.charge_permille is not None
    assert status.roll_mrad == 0
    assert status.pitch_mrad == 0
    counters = sim.state().extended
    assert counters is not None
    assert counters.active


@pytest.mark.parametrize(
    "sim",
    [{"extended": True, "battery_percent": 50.0, "battery_drain_percent_per_s": 5.0}],
    indirect=True,
)
def test_battery_drains_and_streaming_stops_without_hellos(
    sim: RobotSimulator, client: ExtendedClient
) -> None:
    client.rcp(Command())
    client.pump(1.2, hello=SMALL)
    charges = [s.charge_permille for s in client.status]
    assert charges[0] is not None
    assert charges[-1] is not None
    assert charges[-1] < charges[0] <= 500
    assert sim.state().extended is not None
    # No more hellos: after the robot watchdog (1 s) the extension stops and status ends.
    assert sim.wait_until(lambda s: s.extended is not None and not s.extended.active, WAIT_S)
    client.drain()
    client.status.clear()
    client.pump(0.4)
    assert client.status == []


def test_cli_has_the_extended_options() -> None:
    args = build_parser().parse_args(["--extended", "--battery-percent", "30"])
    assert args.extended
    assert args.battery_percent == 30.0
    assert not build_parser().parse_args([]).extended
