"""A bare UDP socket that plays the robot's side of the wire, for link tests."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable

from ocu.profile import RobotProfile
from ocu.protocol import MotorRecord, RemoteControlPacket, TelemetryPacket
from ocu.protocol.wire import make_codec


class RobotPeer:
    """Receives RCPs and sends telemetry from a real socket on 127.0.0.1."""

    def __init__(self, profile: RobotProfile) -> None:
        self.codec = make_codec(profile)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.address: tuple[str, int] = self.sock.getsockname()
        self.tick = 0

    def close(self) -> None:
        """Close the socket."""
        self.sock.close()

    def recv_rcp(
        self, timeout_s: float = 2.0
    ) -> tuple[RemoteControlPacket, float, tuple[str, int]]:
        """Next RCP, its arrival time (monotonic) and its source; TimeoutError if none."""
        self.sock.settimeout(timeout_s)
        data, source = self.sock.recvfrom(65536)
        arrived = time.monotonic()
        packet = self.codec.decode(data)
        assert isinstance(packet, RemoteControlPacket)
        return packet, arrived, source

    def recv_until(
        self, predicate: Callable[[RemoteControlPacket], bool], timeout_s: float = 2.0
    ) -> tuple[RemoteControlPacket, float]:
        """First RCP that satisfies predicate before the deadline."""
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError("no matching RCP before the deadline")
            packet, arrived, _ = self.recv_rcp(remaining)
            if predicate(packet):
                return packet, arrived

    def drain(self) -> int:
        """Discard queued datagrams; how many there were."""
        self.sock.setblocking(False)
        count = 0
        try:
            while True:
                self.sock.recvfrom(65536)
                count += 1
        except BlockingIOError:
            return count
        finally:
            self.sock.setblocking(True)

    def send_telemetry(self, to: tuple[str, int], tick_step: int = 1000) -> None:
        """Send one telemetry packet with the next tick."""
        self.tick += tick_step
        packet = TelemetryPacket(tick=self.tick, motors=(MotorRecord(device_id=4),))
        self.sock.sendto(self.codec.encode(packet), to)

    def send_raw(self, data: bytes, to: tuple[str, int]) -> None:
        """Send any bytes."""
        self.sock.sendto(data, to)
